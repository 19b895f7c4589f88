// The status page: the counts per line, an overview of every drive (one table row each, kept
// and filled in place), and one drive's detail, opened on demand. Every 2 s it fetches only
// what it shows: the overview rows of the drives changed since its last answer, the lines,
// and the open drive. Sorting and filtering fetch nothing. No libraries, no network access
// beyond this server, text only through textContent.
"use strict";

const PERIOD_MS = 2000;
const FULL_EVERY_MS = 30000;  // the whole overview again: a drive a reload removed goes
const TOKEN_HEADER = "X-Changes-Token";
const ALARM_BITS = new Set(["trip", "error", "trip_lock", "warning", "fault", "alarm",
  "voltage_exceeded", "torque_exceeded", "timer_exceeded"]);

// A value is stale when it is older than twice its poll interval and at least its interval
// plus 10 s (polled every 200 ms: after 10.2 s; every second: 11 s; every minute: 2 min),
// 30 s for one polled on no schedule; every value of a drive that is down is stale.
const STALE_UNSCHEDULED_S = 30;

function staleAfter(interval) {
  if (typeof interval !== "number" || !(interval > 0)) return STALE_UNSCHEDULED_S;
  return Math.max(2 * interval, interval + 10);
}

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

function setText(node, text) {  // only a change touches the page, in its text node
  const only = node.firstChild;
  if (only !== null && only === node.lastChild && only.nodeType === Node.TEXT_NODE) {
    if (only.data !== text) only.data = text;
  } else if (node.textContent !== text) {
    node.textContent = text;
  }
}

function setClass(node, cls) {
  if (node.className !== cls) node.className = cls;
}

function age(seconds) {
  if (seconds < 60) return `${Math.max(0, Math.round(seconds))} s`;
  if (seconds < 3600) return `${Math.round(seconds / 60)} min`;
  if (seconds < 172800) return `${(seconds / 3600).toFixed(1)} h`;
  return `${Math.round(seconds / 86400)} d`;
}

function words(name) {
  return name.replace(/_/g, " ");
}

async function getJson(path) {
  const response = await fetch(path, { cache: "no-store" });
  if (!response.ok && response.status !== 503) throw new Error(`${path}: ${response.status}`);
  return response.json();
}

// The server's wall clock, learnt from the overview's rows (their `updated` plus `age` is
// the server's time of the answer): ages are counted on it, whatever this computer's clock.
let clockOffset = 0;  // the server's clock minus this computer's, seconds

function serverNow() {
  return Date.now() / 1000 + clockOffset;
}

function learnClock(rows, receivedAt) {
  for (const r of rows) {
    if (typeof r.updated === "number" && typeof r.age === "number") {
      clockOffset = r.updated + r.age - receivedAt;
      return;
    }
  }
}

// ---- What the reader chose: filters, sort, the open drive (kept in the address's #) ----

const chosen = { line: "", state: "", text: "", sort: "state", descending: false, drive: "" };
const DESCENDING_FIRST = new Set(["alarms", "settings", "faults", "errors", "age"]);

function readHash() {
  const found = new URLSearchParams(location.hash.slice(1));
  chosen.line = found.get("line") || "";
  chosen.state = found.get("state") || "";
  chosen.text = (found.get("find") || "").toLowerCase();
  const sort = found.get("sort") || "state";
  chosen.descending = sort.startsWith("-");
  chosen.sort = sort.replace(/^-/, "");
  if (!SORTS[chosen.sort]) chosen.sort = "state";
  chosen.drive = found.get("drive") || "";
  document.getElementById("filter-state").value = chosen.state;
  document.getElementById("filter-text").value = found.get("find") || "";
}

function saveHash() {
  const out = new URLSearchParams();
  if (chosen.drive) out.set("drive", chosen.drive);
  if (chosen.line) out.set("line", chosen.line);
  if (chosen.state) out.set("state", chosen.state);
  const text = document.getElementById("filter-text").value.trim();
  if (text) out.set("find", text);
  if (chosen.sort !== "state" || chosen.descending) {
    out.set("sort", `${chosen.descending ? "-" : ""}${chosen.sort}`);
  }
  const hash = out.toString();
  if (location.hash.slice(1) === hash) return;
  history.replaceState(null, "", hash ? `#${hash}` : location.href.split("#")[0]);
}

// ---- The overview: one entry per drive, keyed by its name; its row drawn only while it is
// near the screen ----

// At 1,008 drives, with every row in the page, a refresh cost a slow computer (CPU slowed
// four times) 110-120 ms of its main thread, most of it Chromium's walks over the rows
// (layout, pre-paint, the intersections of content-visibility) whenever one changed or
// moved, and its first view up to 2.1 s (benchmark 11). Only the rows on the screen, and a
// screen above and below it, are in the table now (at most some 90 on a 900 px screen),
// the others stand in as its height: every drive stays found by the filters, the sort and
// the scroll bar, and a printout draws every row.
const entries = new Map();  // drive -> {name, data, place, rank, haystack, shown, row...}
let shownRows = [];  // the entries shown (not filtered out), in the table's order
let drawnRows = [];  // the entries whose rows are in the table now, in its order
let places = 0;  // the configuration's order, as the full overview gives it
let changesToken = "";
let fullAt = 0;  // when the whole overview was last asked for
const driveTable = document.getElementById("drives");
const driveBody = driveTable.querySelector("tbody");
const collator = new Intl.Collator(undefined, { numeric: true });

// The bus as pkwbus's documents name it; a PROFIBUS DP slave's state in the live list.
const BUSES = { fc: "FC", uss: "USS", profibus: "PROFIBUS DP" };
const BUS_SHORT = { profibus: "DP" };

function busOf(d) {
  return BUSES[d.protocol] || d.protocol || "";
}

// (Roles: the table's rows are laid out as boxes, status.css, and keep a table's meaning.)
const ROW = el("tr", { role: "row" },
  el("td", { class: "name", role: "cell" }, el("a", {})),
  el("td", { class: "line", role: "cell" }),
  el("td", { class: "bus", role: "cell" }, el("span", { class: "v" })),
  el("td", { class: "num address", role: "cell" }),
  el("td", { class: "state", role: "cell" }, el("span", { class: "v" })),
  el("td", { class: "alarms", role: "cell" },
    el("span", { class: "v" }, el("span", { class: "alarm" }), el("span", { class: "warning" }))),
  el("td", { class: "num settings", role: "cell" }, el("span", { class: "v" })),
  el("td", { class: "num faults", role: "cell" }, el("span", { class: "v" })),
  el("td", { class: "num errors", role: "cell" }, el("span", { class: "v" })),
  el("td", { class: "num age", role: "cell" }, el("span", { class: "v" })));

function makeEntry(name) {
  return { name, data: null, row: null, place: places++, rank: 3, haystack: "", shown: true,
    index: -1 };
}

function makeRow(e) {  // its row, made when it first comes near the screen, then kept
  const row = ROW.cloneNode(true);
  row.dataset.drive = e.name;
  const cells = row.cells;
  const link = cells[0].firstChild;
  link.href = `#drive=${encodeURIComponent(e.name)}`;
  link.textContent = e.name;
  const said = cells[5].firstChild;
  Object.assign(e, { row, line: cells[1], busCell: cells[2], bus: cells[2].firstChild,
    address: cells[3], state: cells[4].firstChild, alarms: cells[5], alarm: said.firstChild,
    warning: said.lastChild, settingsCell: cells[6], settings: cells[6].firstChild,
    faultsCell: cells[7], faults: cells[7].firstChild, errorsCell: cells[8],
    errors: cells[8].firstChild, age: cells[9].firstChild });
}

function rankOf(d) {  // down first, then alarms, warnings, up, in maintenance
  if (d.state === "maintenance") return 4;
  if (d.state === "down") return 0;
  if (d.alarms.length) return 1;
  if (d.warnings.length) return 2;
  return 3;
}

function fillEntry(e, d) {  // what sorts and filters it; its row is drawn by drawRows
  e.data = d;
  e.rank = rankOf(d);
  const dp = d.dp_state ? words(d.dp_state) : "";
  e.haystack = [d.name, d.line, `${d.address}`, d.state, busOf(d), dp, d.alarms.join("; "),
    d.warnings.join("; ")].join("\n").toLowerCase();
}

function drawRow(e, now) {  // only a change touches the page (setText, setClass)
  const d = e.data;
  setText(e.line, d.line);
  const bus = BUS_SHORT[d.protocol] || busOf(d);
  const dp = d.dp_state ? words(d.dp_state) : "";
  setText(e.bus, dp ? `${bus} ${dp}` : bus);
  const busTitle = dp ? `${busOf(d)}: ${dp} (its state in the live list)` : busOf(d);
  if (e.busCell.title !== busTitle) e.busCell.title = busTitle;
  setClass(e.busCell, d.dp_state && d.dp_state !== "data_exchange" ? "bus bad" : "bus");
  setText(e.address, `${d.address}`);
  setText(e.state, d.state);
  const alarms = d.alarms.join("; ");
  const warnings = d.warnings.join("; ");
  setText(e.alarm, alarms);
  setText(e.warning, alarms && warnings ? `; ${warnings}` : warnings);
  const all = d.alarms.concat(d.warnings).join("\n");
  if (e.alarms.title !== all) e.alarms.title = all;
  const changed = d.settings_changed;
  setText(e.settings, typeof changed === "number" ? `${changed}` : "-");
  setClass(e.settingsCell, changed ? "num settings bad" : "num settings");
  setText(e.faults, `${d.faults}`);
  setClass(e.faultsCell, d.faults ? "num faults bad" : "num faults");
  setText(e.errors, `${d.telegram_errors}`);
  setClass(e.errorsCell, d.telegram_errors ? "num errors bad" : "num errors");
  setText(e.age, typeof d.updated === "number" ? age(now - d.updated) : "none yet");
  const flag = d.alarms.length ? " alarm" : (d.warnings.length ? " warning" : "");
  setClass(e.row, `${d.state}${flag}${e.name === openName ? " open" : ""}`);
}

let rowHeight = 0;  // measured on a drawn row (a zoom: again); all rows are of one height
let everyRow = false;  // a printout: every row shown is drawn

// The rows shown from a screen above the screen to a screen below it, in the table, in
// their order (moving the fewest), each filled; the others stand in as the table's height.
function drawRows(now = serverNow()) {
  const count = shownRows.length;
  const height = rowHeight || 30;
  let from = 0, to = count;
  if (!everyRow) {
    const top = driveBody.getBoundingClientRect().top;
    const screen = window.innerHeight;
    from = Math.min(count, Math.max(0, Math.floor((-screen - top) / height)));
    to = Math.max(from, Math.min(count, Math.ceil((2 * screen - top) / height)));
  }
  const wanted = shownRows.slice(from, to);
  const keep = new Set(wanted);
  for (const e of drawnRows) if (!keep.has(e)) e.row.remove();
  let node = driveBody.firstChild;
  wanted.forEach((e, i) => {
    if (!e.row) makeRow(e);
    drawRow(e, now);
    if (e.index !== from + i) {  // its place for assistive technology (aria-rowindex)
      e.index = from + i;
      e.row.setAttribute("aria-rowindex", `${e.index + 2}`);
    }
    if (e.row === node) node = node.nextSibling;
    else driveBody.insertBefore(e.row, node);
  });
  drawnRows = wanted;
  const above = `${from * height}px`, below = `${(count - to) * height}px`;
  if (driveBody.style.paddingTop !== above) driveBody.style.paddingTop = above;
  if (driveBody.style.paddingBottom !== below) driveBody.style.paddingBottom = below;
  if (!rowHeight && wanted.length) {
    rowHeight = wanted[0].row.getBoundingClientRect().height;
    if (rowHeight && Math.abs(rowHeight - height) > 0.01) drawRows(now);
  }
}

let drawQueued = false;

function drawRowsSoon() {  // at the next frame, before it is painted
  if (drawQueued) return;
  drawQueued = true;
  requestAnimationFrame(() => {
    drawQueued = false;
    drawRows();
  });
}

window.addEventListener("scroll", drawRowsSoon, { passive: true });
window.addEventListener("resize", () => {  // a zoom, too: the rows' height is measured again
  rowHeight = 0;
  drawRowsSoon();
});
window.addEventListener("beforeprint", () => {  // a printout shows every row
  everyRow = true;
  drawRows();
});
window.addEventListener("afterprint", () => {
  everyRow = false;
  drawRows();
});

const SORTS = {  // each row's key for a column
  name: (e) => e.name,
  line: (e) => e.data.line,
  bus: (e) => `${busOf(e.data)} ${e.data.dp_state || ""}`,
  address: (e) => e.data.address,
  state: (e) => e.rank,
  alarms: (e) => e.data.alarms.length * 10000 + e.data.warnings.length,
  settings: (e) => (typeof e.data.settings_changed === "number" ? e.data.settings_changed : -1),
  faults: (e) => e.data.faults,
  errors: (e) => e.data.telegram_errors,
  // In whole seconds, and under 10 s all alike: the rows do not change places at every
  // refresh as their newest values come in. None yet: the oldest.
  age: (e, now) => {
    if (typeof e.data.updated !== "number") return Infinity;
    const seconds = now - e.data.updated;
    return seconds < FRESH_S ? 0 : Math.round(seconds);
  },
};
const FRESH_S = 10;

function sortRows() {  // the entries shown, in the chosen order (drawRows draws them)
  const key = SORTS[chosen.sort];
  const sign = chosen.descending ? -1 : 1;
  const now = serverNow();
  const keyed = [];
  for (const e of entries.values()) if (e.shown) keyed.push([key(e, now), e]);
  keyed.sort(([a, x], [b, y]) => {
    const order = typeof a === "string" ? collator.compare(a, b) : (a < b ? -1 : (a > b ? 1 : 0));
    return sign * order || x.place - y.place;
  });
  shownRows = keyed.map(([, e]) => e);
  for (const button of document.querySelectorAll("#drives th button")) {
    const th = button.parentElement;
    const sorted = button.dataset.sort === chosen.sort;
    const aria = sorted ? (chosen.descending ? "descending" : "ascending") : "none";
    if (th.getAttribute("aria-sort") !== aria) th.setAttribute("aria-sort", aria);
  }
}

function matches(e) {
  const d = e.data;
  if (chosen.line && d.line !== chosen.line) return false;
  switch (chosen.state) {
    case "attention": if (e.rank > 2) return false; break;
    case "alarm": if (!d.alarms.length) return false; break;
    case "warning": if (!d.warnings.length) return false; break;
    case "settings": if (!d.settings_changed) return false; break;
    case "up": case "down": case "maintenance": if (d.state !== chosen.state) return false; break;
    default: break;
  }
  return !chosen.text || e.haystack.includes(chosen.text);
}

function filterRows() {
  let shown = 0;
  for (const e of entries.values()) {
    e.shown = matches(e);
    if (e.shown) shown += 1;
  }
  const rows = `${shown + 1}`;  // the head's row, and a row per drive shown
  if (driveTable.getAttribute("aria-rowcount") !== rows) {
    driveTable.setAttribute("aria-rowcount", rows);
  }
  setText(document.getElementById("shown-count"),
    shown === entries.size ? `(${entries.size})` : `(${shown} of ${entries.size} shown)`);
  document.getElementById("no-match").hidden = shown > 0 || entries.size === 0;
}

// The overview's rows as the API answered them: `complete` when all drives were asked for,
// so that a drive not in it is gone.
function applyOverview(rows, complete) {
  const seen = complete ? new Set() : null;
  for (const d of rows) {
    let e = entries.get(d.name);
    if (!e) entries.set(d.name, e = makeEntry(d.name));
    if (seen) seen.add(d.name);
    fillEntry(e, d);
  }
  if (seen) {
    for (const name of entries.keys()) if (!seen.has(name)) entries.delete(name);
  }
  filterRows();
  sortRows();
  drawRows();
}

async function refreshOverview() {
  const complete = !changesToken || Date.now() - fullAt >= FULL_EVERY_MS;
  const since = complete ? "" : `&changed_since=${encodeURIComponent(changesToken)}`;
  const response = await fetch(`api/v1/drives?view=overview${since}`, { cache: "no-store" });
  if (!response.ok) throw new Error(`api/v1/drives: ${response.status}`);
  const rows = await response.json();
  learnClock(rows, Date.now() / 1000);
  if (complete) fullAt = Date.now();
  changesToken = response.headers.get(TOKEN_HEADER) || "";
  return { rows, complete };
}

// ---- The counts per line: drives, up, down, in maintenance, with alarms or warnings ----

const lineRows = new Map();  // line -> {row, cells}
const COUNTS = ["drives", "up", "down", "maintenance", "alarm", "warning"];
const COUNT_STATE = { drives: "", up: "up", down: "down", maintenance: "maintenance",
  alarm: "alarm", warning: "warning" };
let lineNames = [];

function countLines() {
  const counts = new Map();
  const total = { drives: 0, up: 0, down: 0, maintenance: 0, alarm: 0, warning: 0 };
  for (const e of entries.values()) {
    const d = e.data;
    let c = counts.get(d.line);
    if (!c) counts.set(d.line, c = { drives: 0, up: 0, down: 0, maintenance: 0, alarm: 0,
      warning: 0 });
    for (const into of [c, total]) {
      into.drives += 1;
      into[d.state] += 1;
      if (d.alarms.length) into.alarm += 1;
      if (d.warnings.length) into.warning += 1;
    }
  }
  return { counts, total };
}

function lineRow(name) {
  const cells = { port: el("td", { class: "port" }), busy: el("td", { class: "num busy" }) };
  const counted = COUNTS.map((key) => {
    const button = el("button", { type: "button", class: "count", "data-of-line": name,
      "data-state": COUNT_STATE[key], title: "show these drives" });
    cells[key] = button;
    return el("td", { class: `num ${key}` }, button);
  });
  const row = el("tr", name === "" ? {} : { "data-line": name },
    el("td", {}, name === "" ? "all lines" : name), cells.port, ...counted, cells.busy);
  return { row, cells };
}

function fillLine(r, c, line) {
  for (const key of COUNTS) {
    setText(r.cells[key], `${c[key]}`);
    const bad = c[key] > 0 && (key === "down" || key === "alarm");
    setClass(r.cells[key], `count${bad ? " bad" : ""}${key === "warning" && c[key] ? " warn" : ""}`);
  }
  if (line && line.master && !line.master.here) {  // hot standby: the instance that masters it
    showMaster(r.cells.port, line.master);
    setText(r.cells.busy, "-");
  } else if (line) {
    if (r.cells.port.dataset.master !== undefined) {
      delete r.cells.port.dataset.master;
      r.cells.port.removeAttribute("title");
    }
    setText(r.cells.port, line.open ? "open" : "closed");
    setClass(r.cells.port, line.open ? "port" : "port bad");
    setText(r.cells.busy,
      line.utilisation === null ? "-" : `${Math.round(line.utilisation * 100)} %`);
  }
}

// A line another instance masters (hot standby): its name, a link to its page where it
// advertises an http(s) URL.
function showMaster(cell, master) {
  const key = `${master.name}\n${master.url || ""}`;
  if (cell.dataset.master === key) return;
  cell.dataset.master = key;
  const url = master.url && /^https?:\/\//i.test(master.url) ? master.url : null;
  const name = url ? el("a", { href: url, class: "master" }, master.name) : master.name;
  cell.replaceChildren("mastered by ", name);
  setClass(cell, "port elsewhere");
  cell.title = url ? `this line runs on ${master.name}: ${url}` : `this line runs on ${master.name}`;
}

function drawLines(lines) {
  const { counts, total } = countLines();
  const names = lines.map((l) => l.name);
  for (const name of counts.keys()) if (!names.includes(name)) names.push(name);
  const zero = { drives: 0, up: 0, down: 0, maintenance: 0, alarm: 0, warning: 0 };
  const body = document.querySelector("#lines tbody");
  const rows = names.map((name) => {
    let r = lineRows.get(name);
    if (!r) lineRows.set(name, r = lineRow(name));
    fillLine(r, counts.get(name) || zero, lines.find((l) => l.name === name));
    return r.row;
  });
  for (const name of [...lineRows.keys()]) {  // a line a reload removed ("": all lines)
    if (name !== "" && !names.includes(name)) lineRows.delete(name);
  }
  if (rows.length !== body.children.length || rows.some((row, i) => body.children[i] !== row)) {
    body.replaceChildren(...rows);
  }
  let all = lineRows.get("");
  if (!all) {
    lineRows.set("", all = lineRow(""));
    document.querySelector("#lines tfoot").append(all.row);
  }
  fillLine(all, total, null);
  const up = lines.filter((l) => l.open).length;
  const elsewhere = lines.filter((l) => l.master && !l.master.here).length;  // hot standby
  const here = lines.length - elsewhere;
  setText(all.cells.port,
    `${up} of ${here} open${elsewhere ? `, ${elsewhere} mastered elsewhere` : ""}`);
  setClass(all.cells.port, up < here ? "port bad" : "port");
  const busy = lines.map((l) => l.utilisation).filter((u) => u !== null);
  setText(all.cells.busy,
    busy.length ? `${Math.round((busy.reduce((a, b) => a + b, 0) / busy.length) * 100)} %` : "-");
  if (names.join("\n") !== lineNames.join("\n")) {  // the line filter's choices
    lineNames = names;
    const select = document.getElementById("filter-line");
    select.replaceChildren(el("option", { value: "" }, "all lines"),
      ...names.map((n) => el("option", { value: n }, n)));
    if (!names.includes(chosen.line)) chosen.line = "";  // a line the address named, gone
    select.value = chosen.line;
  }
}

// ---- One drive's detail: opened on demand, refreshed with ?drive= every 2 s ----

let openName = "";
let detail = null;  // {name, token, drive, shape, parts...}
const SVG = "http://www.w3.org/2000/svg";

// The open drive's values over the last 15 minutes (/api/v1/trends?drive=), every 15 s.
let trendData = {};  // parameter -> points
let trendsFetched = 0;  // when they were last asked for
let trendsVersion = 0;  // counts the trends that arrived: a row draws its sparkline anew
const TREND_PERIOD_MS = 15000;

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

async function refreshTrends(d) {  // true: new trends
  if (Date.now() - trendsFetched < TREND_PERIOD_MS) return false;
  trendsFetched = Date.now();
  const found = await getJson(`api/v1/trends?drive=${encodeURIComponent(d.name)}`);
  if (detail !== d) return false;
  trendData = found[d.name] || {};
  trendsVersion += 1;
  return true;
}

function every(interval) {
  if (typeof interval !== "number" || !(interval > 0)) return "polled on no schedule";
  return interval < 1 ? `polled every ${Math.round(interval * 1000)} ms`
    : `polled every ${age(interval)}`;
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

function fillRow(r, drive, v, now) {
  const seconds = now - v.timestamp;
  const limit = staleAfter(v.interval);
  const shown = v.shown || `${v.value}`;  // to its resolution; the API keeps full precision
  setClass(r.row, seconds > limit || !drive.up ? "stale" : "");
  setText(r.title, v.name || "");
  const unit = v.shown_unit ?? v.unit;
  setText(r.value, unit ? `${shown} ${unit}` : shown);
  if (r.value.title !== `${v.value}`) r.value.title = `${v.value}`;
  setText(r.age, age(seconds));
  const why = `${every(v.interval)}: stale after ${age(limit)}`;
  if (r.age.title !== why) r.age.title = why;
  if (r.drawnTrends !== trendsVersion) {  // the sparklines change with the trends, every 15 s
    drawTrend(r.spark, trendData[r.row.dataset.parameter] || []);
    r.drawnTrends = trendsVersion;
  }
}

// What makes the detail's shape: its heading, status bits, alarms, live list state and
// values. Its counts, values and ages are filled in place; a new shape draws it anew.
function shapeOf(drive) {
  return JSON.stringify([drive.name, drive.up, drive.line, drive.address, drive.protocol,
    drive.status_word, drive.status, drive.alarms, drive.maintenance, drive.dp,
    drive.values.map((v) => [v.parameter, v.index])]);
}

function stateOf(drive) {
  return drive.maintenance ? "maintenance" : (drive.up ? "up" : "down");
}

function dpPart(dp) {  // a PROFIBUS DP slave: its place in the live list
  const ident = dp.ident === null ? "-" : `0x${dp.ident.toString(16).padStart(4, "0")}`;
  const owner = dp.owner === null ? "none" : `${dp.owner}`;
  const diag = dp.diagnosed === null ? "none read yet"
    : (dp.diagnosis.length ? dp.diagnosis.join(", ") : "no flag set");
  const when = dp.diagnosed === null ? "" : ` (${new Date(dp.diagnosed * 1000).toLocaleString()})`;
  return el("p", { class: `dp${dp.state === "data_exchange" ? "" : " bad"}` },
    "PROFIBUS DP: ", el("span", { class: "dp-state" }, words(dp.state)),
    `; ident ${ident}; owning master ${owner}; latest diagnosis: ${diag}${when}`);
}

function drawDetail(d) {
  const drive = d.drive;
  const state = stateOf(drive);
  const bits = Object.entries(drive.status || {}).filter(([, on]) => on)
    .map(([name]) => el("span", { class: ALARM_BITS.has(name) ? "alarm" : "" }, words(name)));
  d.rows = drive.values.map((v) => valueRow(v.index ? `${v.parameter}[${v.index}]` : v.parameter));
  const alarms = (drive.alarms || []).map((a) => {
    const since = new Date(a.since * 1000).toLocaleString();
    return el("li", { class: a.kind === "alarm" ? "alarm" : "warning", "data-code": a.code },
      `${a.kind} ${a.code}`, a.text ? ` ${a.text}` : "", ` (${a.parameter}, since ${since})`);
  });
  const word = drive.status_word === null ? "no status word"
    : `status word 0x${drive.status_word.toString(16).padStart(4, "0")}`;
  const held = drive.maintenance;  // nothing goes out to it: neither up nor down
  const heldNote = held ? el("p", { class: "maintenance" },
    `in maintenance since ${new Date(held.since * 1000).toLocaleString()}`,
    held.reason ? `: ${held.reason}` : "", " - nothing goes out to it") : "";
  d.faults = el("span", {});
  d.errors = el("span", {});
  d.settings = el("div", { class: "settings" });  // drawSettings fills it
  d.settings.hidden = true;
  d.sweptAge = null;
  d.drawnSettings = -1;
  let values;
  if (drive.values.length) {
    values = el("table", { class: "values" }, el("thead", {}, el("tr", {},
      el("th", {}, "parameter"), el("th", {}, "name"), el("th", { class: "num" }, "value"),
      el("th", {}, "15 min"), el("th", { class: "num" }, "age"))),
      el("tbody", {}, ...d.rows.map((r) => r.row)));
  } else {
    const polled = drive.polled || 0;
    values = el("p", { class: "nothing" }, !polled ? "Nothing is polled on this drive."
      : drive.up || held
        ? `None of the ${polled === 1 ? "value" : `${polled} values`} polled has been read yet.`
        : "No value read from this drive: it is down.");
  }
  const body = document.getElementById("detail-body");
  body.className = state;
  body.replaceChildren(
    el("h2", {}, `${drive.name} `, el("span", { class: "state" }, state)),
    el("p", { class: "where" },
      `line ${drive.line}, address ${drive.address}, ${drive.protocol}, ${word}`),
    heldNote,
    el("div", { class: "counts" }, d.faults, d.errors, " since the service started"),
    bits.length ? el("div", { class: "bits" }, ...bits) : "",
    alarms.length ? el("ul", { class: "alarms" }, ...alarms) : "",
    drive.dp ? dpPart(drive.dp) : "",
    d.settings,
    values);
}

function fillCounts(d, drive) {
  setText(d.faults, `${drive.faults} faults`);
  setClass(d.faults, drive.faults ? "alarm" : "");
  setText(d.errors, `${drive.telegram_errors} telegram errors`);
  setClass(d.errors, drive.telegram_errors ? "alarm" : "");
}

function fillDetail(d) {
  const drive = d.drive;
  if (!drive) return;
  const shape = shapeOf(drive);
  if (shape !== d.shape) {
    drawDetail(d);
    d.shape = shape;
  }
  const now = serverNow();
  fillCounts(d, drive);
  fillSettings(d, now);
  drive.values.forEach((v, i) => fillRow(d.rows[i], drive, v, now));
  drawWritable(drive);
}

function showDetail(name) {
  const aside = document.getElementById("detail");
  aside.hidden = !name;
  if (name) aside.dataset.drive = name;
  else delete aside.dataset.drive;
  document.getElementById("board").classList.toggle("open", !!name);
}

function markOpen(name, on) {
  const e = entries.get(name);
  if (e && e.row) e.row.classList.toggle("open", on);
}

function openDrive(name) {
  if (name === openName) return;
  closeDrive();
  openName = chosen.drive = name;
  detail = { name, token: "", drive: null, shape: "", rows: [] };
  trendData = {};
  trendsFetched = 0;
  settingsAt = 0;
  settingsData = null;
  settingsVersion += 1;
  driveEventsAt = 0;
  pending = null;
  document.getElementById("write-button").textContent = "Write";
  document.getElementById("write-result").hidden = true;
  document.getElementById("drive-events").hidden = true;
  document.getElementById("detail-body").replaceChildren(
    el("h2", {}, `${name} `), el("p", { class: "note" }, "loading..."));
  markOpen(name, true);
  showDetail(name);
  saveHash();
  const e = entries.get(name);
  if (e && window.matchMedia("(max-width: 1250px)").matches) {
    document.getElementById("detail").scrollIntoView({ block: "start" });
  }
  refreshDetail().catch(detailProblem);
}

function closeDrive() {
  if (!openName) return;
  markOpen(openName, false);
  openName = chosen.drive = "";
  detail = null;
  writables = new Map();
  document.getElementById("write-target").replaceChildren();
  showDetail("");
  saveHash();
}

function detailProblem(error) {
  const problem = document.getElementById("problem");
  problem.hidden = false;
  problem.textContent = `no answer from pkwbus (${error.message}): showing the last data`;
}

// The open drive's view, only when it changed since its last answer: {d, views, token},
// views null when pkwbus has no such drive.
async function fetchDetail() {
  const d = detail;
  if (!d) return null;
  const since = d.token ? `&changed_since=${encodeURIComponent(d.token)}` : "";
  const response = await fetch(`api/v1/drives?drive=${encodeURIComponent(d.name)}${since}`,
    { cache: "no-store" });
  if (response.status === 404) return { d, views: null, token: "" };
  if (!response.ok) throw new Error(`api/v1/drives?drive=: ${response.status}`);
  return { d, views: await response.json(), token: response.headers.get(TOKEN_HEADER) || "" };
}

// Then what is due of its trends, settings and log: each fills it when it has arrived.
function applyDetail(found) {
  if (!found || detail !== found.d) return;  // another drive opened meanwhile
  const d = found.d;
  if (found.views === null) {
    d.drive = null;
    d.shape = "";
    document.getElementById("detail-body").replaceChildren(el("h2", {}, d.name),
      el("p", { class: "nothing" }, "pkwbus has no drive of this name (any more)."));
    return;
  }
  d.token = found.token;
  if (found.views.length) d.drive = found.views[0];
  fillDetail(d);
  if (!d.drive) return;
  // Each drawn as it arrives: the sparklines do not wait for the log (a query of the
  // history) or the settings.
  for (const due of [refreshTrends(d), refreshSettings(d), refreshDriveEvents(d)]) {
    due.then((changed) => {
      if (changed && detail === d) fillDetail(d);
    }, () => {});
  }
}

async function refreshDetail() {
  applyDetail(await fetchDetail());
}

// ---- The open drive's settings that differ from its baseline (/api/v1/drives/{drive}/settings),
// asked for at its opening and every 30 s, beside the 2 s refreshes, not in them ----

const SETTINGS_EVERY_MS = 30000;
let settingsAt = 0;  // when they were last asked for
let settingsVersion = 0;  // counts the answers: the detail draws its settings anew
let settingsData = null;  // {swept, every, count, changed} of the open drive; null: nothing

async function settingsOf(name) {  // what to show of one drive's settings; null: nothing
  const path = `api/v1/drives/${encodeURIComponent(name)}/settings`;
  const response = await fetch(path, { cache: "no-store" });
  if (response.status === 404) return null;  // not swept
  if (!response.ok) throw new Error(`${path}: ${response.status}`);
  const view = await response.json();
  const parameters = view.parameters || [];
  return { swept: view.swept, every: view.every, count: parameters.length,
    changed: parameters.filter((p) => p.changed) };
}

async function refreshSettings(d) {  // true: new settings
  if (!d.drive.settings) {  // not swept: nothing to show, nothing asked
    const had = settingsData !== null;
    if (had) settingsVersion += 1;
    settingsData = null;
    return had;
  }
  if (Date.now() - settingsAt < SETTINGS_EVERY_MS) return false;
  settingsAt = Date.now();
  const found = await settingsOf(d.name);  // no answer: the last one stays
  if (detail !== d) return false;
  settingsData = found;
  settingsVersion += 1;
  return true;
}

function shownSetting(value, unit) {
  if (value === null || value === undefined) return "?";
  return unit ? `${value} ${unit}` : `${value}`;
}

function drawSettings(d, found) {
  const box = d.settings;
  d.sweptAge = null;
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
    d.sweptAge = el("span", { class: "swept-age" });
    sweep = el("span", {}, `last complete sweep ${new Date(found.swept).toLocaleString()} (`,
      d.sweptAge, " ago)");
  }
  const often = found.every ? `, every ${age(found.every)}` : "";
  const parts = [el("p", { class: "sweep" }, differ, "; ", sweep, often)];
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
      d.name, "/settings/baseline (write token); a write through pkwbus ",
      "moves the baseline itself"));
  }
  box.replaceChildren(...parts);
  box.hidden = false;
}

function fillSettings(d, now) {
  if (d.drawnSettings !== settingsVersion) {
    drawSettings(d, settingsData);
    d.drawnSettings = settingsVersion;
  }
  if (d.sweptAge && settingsData && settingsData.swept) {
    setText(d.sweptAge, age(now - Date.parse(settingsData.swept) / 1000));
  }
}

// ---- The drives' own log entries (/api/v1/events): the newest 20 of all drives, and the
// open drive's newest 10, each every 10 s ----

const EVENTS_EVERY_MS = 10000;
let eventsAt = 0;
let driveEventsAt = 0;
const TIME_FROM = { runtime: "the drive's runtime", drive_clock: "the drive's clock",
  seen: "when read" };
// Red: a trip, or a setting nobody audited; a SINAMICS alarm (A-number) is a warning's kind.
const BAD_EVENTS = new Set(["fault", "setting"]);

function eventRow(e, withDrive) {
  const link = el("a", { href: `#drive=${encodeURIComponent(e.drive)}`, "data-open": e.drive },
    e.drive);
  return el("tr", { class: BAD_EVENTS.has(e.kind) ? "bad" : "" },
    el("td", {}, new Date(e.time).toLocaleString()), withDrive ? el("td", {}, link) : "",
    el("td", {}, e.kind), el("td", {}, e.text ? `${e.code} ${e.text}` : e.code),
    el("td", {}, e.value ?? ""), el("td", {}, TIME_FROM[e.time_source] || e.time_source));
}

function drawEvents(section, events, withDrive) {
  section.querySelector("tbody").replaceChildren(...events.map((e) => eventRow(e, withDrive)));
  section.hidden = events.length === 0;
}

async function refreshEvents() {
  if (Date.now() - eventsAt < EVENTS_EVERY_MS) return;
  eventsAt = Date.now();
  const found = (await getJson("api/v1/events?limit=20")).events || [];
  drawEvents(document.getElementById("events"), found, true);
}

async function refreshDriveEvents(d) {  // drawn here: the detail's values unchanged
  if (Date.now() - driveEventsAt < EVENTS_EVERY_MS) return false;
  driveEventsAt = Date.now();
  const path = `api/v1/events?drive=${encodeURIComponent(d.name)}&limit=10`;
  const found = (await getJson(path)).events || [];
  if (detail === d) drawEvents(document.getElementById("drive-events"), found, false);
  return false;
}

// ---- The last write attempts, once a token is given ----

// The token for the audit log: in this variable only (no storage), for this page's life.
let auditToken = "";

function drawWrites(entriesOfAudit) {
  const rows = entriesOfAudit.map((e) => {
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
  setText(document.getElementById("token-note"), "");
  refreshWrites().catch((error) => {
    setText(document.getElementById("token-note"), error.message);
    showResult(`token: ${error.message}`, true);
  });
});

// ---- The write form: the open drive's writable parameters ----

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

function drawWritable(drive) {  // the choices change only with the drive's list
  const select = document.getElementById("write-target");
  const list = drive.writable || [];
  const keys = list.map((w) => writeKey(drive.name, w));
  const same = keys.length === select.options.length
    && keys.every((k, i) => select.options[i].value === k);
  writables = new Map(list.map((w, i) => [keys[i], { drive: drive.name, w }]));
  if (!same) {
    const was = select.value;
    select.replaceChildren(...list.map((w, i) =>
      el("option", { value: keys[i] }, w.name ? `${keys[i]} ${w.name}` : keys[i])));
    if (writables.has(was)) select.value = was;
  }
  document.getElementById("write-none").hidden = keys.length > 0;
  document.getElementById("write-form").hidden = keys.length === 0;
  const item = writables.get(select.value);
  setText(document.getElementById("write-now"), item ? describeWritable(item.w) : "");
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
  document.getElementById("write-result").hidden = true;  // it was of another parameter
  const item = writables.get(document.getElementById("write-target").value);
  document.getElementById("write-now").textContent = item ? describeWritable(item.w) : "";
});

// ---- The reader's doings: sort, filter, open and close a drive ----

document.querySelector("#drives thead").addEventListener("click", (event) => {
  const button = event.target.closest("button[data-sort]");
  if (!button) return;
  const key = button.dataset.sort;
  chosen.descending = key === chosen.sort ? !chosen.descending : DESCENDING_FIRST.has(key);
  chosen.sort = key;
  sortRows();
  drawRows();
  saveHash();
});

driveBody.addEventListener("click", (event) => {
  const row = event.target.closest("tr[data-drive]");
  if (!row || event.ctrlKey || event.metaKey || event.shiftKey || event.button !== 0) return;
  event.preventDefault();  // its link would lose the filters in the address
  if (row.dataset.drive === openName) closeDrive(); else openDrive(row.dataset.drive);
});

document.addEventListener("click", (event) => {
  const link = event.target.closest("a[data-open]");
  if (!link || event.ctrlKey || event.metaKey || event.shiftKey) return;
  event.preventDefault();
  openDrive(link.dataset.open);
});

document.getElementById("lines").addEventListener("click", (event) => {
  const button = event.target.closest("button.count");
  if (!button) return;
  chosen.line = button.dataset.ofLine;
  chosen.state = button.dataset.state;
  document.getElementById("filter-line").value = chosen.line;
  document.getElementById("filter-state").value = chosen.state;
  filterRows();
  sortRows();
  drawRows();
  saveHash();
});

function filtersChanged() {
  chosen.line = document.getElementById("filter-line").value;
  chosen.state = document.getElementById("filter-state").value;
  chosen.text = document.getElementById("filter-text").value.trim().toLowerCase();
  filterRows();
  sortRows();
  drawRows();
  saveHash();
}

document.getElementById("filters").addEventListener("input", filtersChanged);
document.getElementById("filters").addEventListener("submit", (event) => event.preventDefault());
document.getElementById("filter-reset").addEventListener("click", () => {
  document.getElementById("filter-line").value = "";
  document.getElementById("filter-state").value = "";
  document.getElementById("filter-text").value = "";
  filtersChanged();
});
document.getElementById("detail-close").addEventListener("click", closeDrive);
document.addEventListener("keydown", (event) => {
  if (event.key === "Escape" && openName) closeDrive();
});
window.addEventListener("hashchange", () => {  // typed or followed by the reader
  readHash();
  document.getElementById("filter-line").value = chosen.line;
  filterRows();
  sortRows();
  drawRows();
  const wanted = chosen.drive;
  if (wanted !== openName) {
    if (wanted) openDrive(wanted); else closeDrive();
  }
});

// ---- The 2 s refresh ----

let running = true;  // false: the refreshes stop (the benchmark times them one by one)

async function refresh() {  // everything asked for at once, then drawn at once
  const [overview, lines, ready, one] = await Promise.all([refreshOverview(),
    getJson("api/v1/lines"), getJson("readyz"), fetchDetail()]);
  applyOverview(overview.rows, overview.complete);
  drawLines(lines);
  applyDetail(one);
  const problem = document.getElementById("problem");
  problem.hidden = ready.writes !== false;
  problem.textContent = ready.reason || "";
  setText(document.getElementById("updated"), `updated ${new Date().toLocaleTimeString()}`);
  refreshEvents().catch(() => {});  // beside the refresh: the log entries wait for the next
  refreshWrites().catch(() => {});
}

async function loop() {
  if (!running) return;
  try {
    await refresh();
  } catch (error) {
    const problem = document.getElementById("problem");
    problem.hidden = false;
    problem.textContent = `no answer from pkwbus (${error.message}): showing the last data`;
  } finally {
    if (running) setTimeout(loop, PERIOD_MS);
  }
}

readHash();
if (chosen.drive) {
  const wanted = chosen.drive;
  chosen.drive = "";
  openDrive(wanted);
}
loop();
