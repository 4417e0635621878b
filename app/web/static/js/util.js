// Small DOM and formatting helpers shared by the pages.

// h("td", {class: "num"}, "12.3") -> element; attributes starting with "on" become listeners.
export function h(tag, attrs = {}, ...children) {
  return fill(document.createElement(tag), attrs, children);
}

// svg("line", {x1: 0, ...}) -> an SVG element, built as h() builds HTML ones.
export function svg(tag, attrs = {}, ...children) {
  return fill(document.createElementNS("http://www.w3.org/2000/svg", tag), attrs, children);
}

function fill(el, attrs, children) {
  for (const [k, v] of Object.entries(attrs || {})) {
    if (v === undefined || v === null || v === false) continue;
    if (k.startsWith("on")) el.addEventListener(k.slice(2), v);
    else if (k === "dataset") Object.assign(el.dataset, v);
    else if (v === true) el.setAttribute(k, "");
    else el.setAttribute(k, v);
  }
  for (const c of children.flat()) {
    if (c === undefined || c === null || c === false) continue;
    el.append(c instanceof Node ? c : document.createTextNode(String(c)));
  }
  return el;
}

export function fmt(x, digits = 1) {
  if (x === null || x === undefined || Number.isNaN(x)) return "-";
  if (typeof x !== "number") return String(x);
  return x.toFixed(digits);
}

export function bytes(n) {
  if (n < 1024) return `${n} B`;
  if (n < 2 ** 20) return `${(n / 1024).toFixed(1)} KiB`;
  return `${(n / 2 ** 20).toFixed(1)} MiB`;
}

export function duration(s) {
  if (s === null || s === undefined) return "-";
  if (s < 120) return `${s.toFixed(1)} s`;
  const m = Math.floor(s / 60);
  return `${m} min ${Math.round(s - 60 * m)} s`;
}

// The log's start as milliseconds since the epoch (UTC) and whether the log said its time zone.
export function logStart(startTime) {
  if (!startTime) return null;
  const zoned = /(Z|[+-]\d\d:?\d\d)$/.test(startTime);
  const ms = Date.parse(zoned ? startTime : `${startTime}Z`);
  return Number.isNaN(ms) ? null : { ms, zoned };
}

// "12.345 s (2024-05-01 10:00:12.345 UTC)": relative time with the absolute time beside it.
export function stamp(t, start) {
  const rel = `${t.toFixed(3)} s`;
  if (!start) return rel;
  const iso = new Date(start.ms + t * 1000).toISOString().replace("T", " ").replace("Z", "");
  return `${rel} (${iso} ${start.zoned ? "UTC" : "log clock"})`;
}

export function utc(iso) {
  if (!iso) return "-";
  const s = logStart(iso);
  return s ? `${new Date(s.ms).toISOString().replace("T", " ").slice(0, 19)} UTC` : iso;
}

// "torsional stiffness at the motor 0.75x the file [0.72, 0.78]": a ratio to the vehicle file's value.
export function ratioWords(label, ratio, lo, hi) {
  return `${label} ${fmt(ratio, 2)}x the file [${fmt(lo, 2)}, ${fmt(hi, 2)}]`;
}

export function badge(status) {
  return h("span", { class: `badge ${status}` }, status);
}

// A failed job's error as the API gives it ({detail, code}), or `fallback` when it has none.
export function jobError(error, fallback) {
  return errorBox(new Error(error ? `${error.detail} [${error.code}]` : fallback));
}

export function errorBox(err) {
  return h("div", { class: "error", role: "alert" }, err.message || String(err));
}

export function progressBar(fraction, label) {
  const pct = Math.round(100 * Math.max(0, Math.min(1, fraction)));
  return h("div", { class: "progress", role: "progressbar", "aria-valuenow": pct, "aria-valuemin": 0,
    "aria-valuemax": 100 }, h("div", { class: "bar", style: `width:${pct}%` }), h("span", {}, label || `${pct} %`));
}

// " · about 40 s left" from a running job's eta_s (the REST status; null early on), "" without one
export function etaText(eta) {
  if (eta === null || eta === undefined || !Number.isFinite(eta)) return "";
  return eta < 120 ? ` · about ${Math.round(eta)} s left` : ` · about ${Math.round(eta / 60)} min left`;
}

export const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// A table whose columns sort on a click; columns: [{key, label, value(row), render(row), num, cls, group}].
// Columns with a `group` get a header row above theirs naming the group once over its columns.
export function sortableTable(columns, rows, { id, initial } = {}) {
  const table = h("table", { class: "sortable", id });
  let sortKey = initial ?? null;
  let dir = 1;
  const head = h("tr", {});
  const body = h("tbody", {});
  const draw = () => {
    const col = columns.find((c) => c.key === sortKey);
    const data = [...rows];
    if (col) {
      const v = col.value || ((r) => r[col.key]);
      data.sort((a, b) => {
        const x = v(a);
        const y = v(b);
        if (x === y) return 0;
        if (x === null || x === undefined || Number.isNaN(x)) return 1;
        if (y === null || y === undefined || Number.isNaN(y)) return -1;
        return (x < y ? -1 : 1) * dir;
      });
    }
    body.replaceChildren(...data.map((r) => h("tr", {}, columns.map((c) =>
      h("td", { class: [c.num ? "num" : null, c.cls].filter(Boolean).join(" ") || null }, c.render ? c.render(r) : fmt((c.value || ((x) => x[c.key]))(r), c.digits ?? 1))))));
    for (const th of head.children) th.dataset.sorted = th.dataset.key === sortKey ? (dir > 0 ? "asc" : "desc") : "";
  };
  for (const c of columns) {
    head.append(h("th", { dataset: { key: c.key }, title: c.title || "sort", class: c.num ? "num" : null,
      onclick: () => { dir = sortKey === c.key ? -dir : 1; sortKey = c.key; draw(); } }, c.label));
  }
  const thead = h("thead", {});
  if (columns.some((c) => c.group)) {
    const groups = h("tr", { class: "group" });
    for (const c of columns) {
      const prev = groups.lastElementChild;
      if (prev && prev.dataset.group === (c.group || "") && c.group) prev.colSpan += 1;
      else groups.append(h("th", { dataset: { group: c.group || "" } }, c.group || ""));
    }
    thead.append(groups);
  }
  thead.append(head);
  table.append(thead, body);
  draw();
  return table;
}
