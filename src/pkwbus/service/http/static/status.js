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

function drawDrive(drive, now) {
  const bits = Object.entries(drive.status || {}).filter(([, on]) => on)
    .map(([name]) => el("span", { class: ALARM_BITS.has(name) ? "alarm" : "" }, words(name)));
  const rows = drive.values.map((v) => {
    const seconds = now - v.timestamp;
    const shown = v.shown || `${v.value}`;  // to its resolution; the API keeps full precision
    const value = v.unit ? `${shown} ${v.unit}` : shown;
    const name = v.index ? `${v.parameter}[${v.index}]` : v.parameter;
    return el("tr", { class: seconds > STALE_SECONDS || !drive.up ? "stale" : "", "data-parameter": name },
      el("td", {}, name), el("td", { class: "title" }, v.name || ""),
      el("td", { class: "num value", title: `${v.value}` }, value),
      el("td", { class: "num age" }, age(seconds)));
  });
  const alarms = (drive.alarms || []).map((a) => {
    const since = new Date(a.since * 1000).toLocaleString();
    return el("li", { class: a.kind === "alarm" ? "alarm" : "warning", "data-code": a.code },
      `${a.kind} ${a.code}`, a.text ? ` ${a.text}` : "", ` (${a.parameter}, since ${since})`);
  });
  const word = drive.status_word === null ? "no status word"
    : `status word 0x${drive.status_word.toString(16).padStart(4, "0")}`;
  return el("div", { class: `drive ${drive.up ? "up" : "down"}`, "data-drive": drive.name },
    el("h3", {}, `${drive.name} `, el("span", { class: "state" }, drive.up ? "up" : "down"),
      ` - line ${drive.line}, address ${drive.address}, ${drive.protocol}, ${word}`),
    el("div", { class: "counts" },
      el("span", { class: drive.faults ? "alarm" : "" }, `${drive.faults} faults`),
      el("span", { class: drive.telegram_errors ? "alarm" : "" },
        `${drive.telegram_errors} telegram errors`), " since the service started"),
    el("div", { class: "bits" }, ...bits),
    alarms.length ? el("ul", { class: "alarms" }, ...alarms) : "",
    el("table", {}, el("thead", {}, el("tr", {}, el("th", {}, "parameter"), el("th", {}, "name"),
      el("th", {}, "value"), el("th", {}, "age"))), el("tbody", {}, ...rows)));
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
  const response = await fetch("/api/v1/audit?limit=10", {
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
  refreshWrites().catch(() => {});
});

async function getJson(path) {
  const response = await fetch(path, { cache: "no-store" });
  if (!response.ok && response.status !== 503) throw new Error(`${path}: ${response.status}`);
  return response.json();
}

async function refresh() {
  const problem = document.getElementById("problem");
  try {
    const [lines, drives, ready] = await Promise.all(
      [getJson("/api/v1/lines"), getJson("/api/v1/drives"), getJson("/readyz")]);
    const now = Date.now() / 1000;
    drawLines(lines);
    document.getElementById("drives").replaceChildren(
      el("h2", {}, "Drives"), ...drives.map((d) => drawDrive(d, now)));
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
