// The analysis' events: the event list, the sortable metrics table (measured / simulated /
// difference with units and the tracking verdict) and an overlay panel for every event with
// torque, gap-open and impact markers, a page at a time, with an optional shared rpm span.
import { api, download, saveBlob } from "./api.js";
import { chartPng, COLORS, seriesData, speedChart } from "./chart.js";
import { badge, errorBox, fmt, h, sortableTable, stamp } from "./util.js";

// name, label, unit shown, factor from the API's SI value, digits
export const METRICS = [
  ["fluctuation_rpm", "fluctuation peak-valley", "rpm", 1, 1],
  ["rise_height_rpm", "rise height (gap open)", "rpm", 1, 1],
  ["gap_open_time_s", "gap-open time", "ms", 1000, 1],
  ["rising_edge_time_s", "rising edge", "ms", 1000, 1],
  ["first_overshoot_rpm", "first overshoot", "rpm", 1, 1],
  ["shuffle_freq_hz", "shuffle frequency", "Hz", 1, 2],
  ["damping_ratio", "damping ratio", "-", 1, 3],
  ["settling_time_s", "settling time", "s", 1, 3],
];
// drivability criteria on the vehicle's acceleration (metrics row's "drivability"), shown measured and simulated
export const FEEL = [
  ["response_delay_s", "delay", "ms", 1000, 0],
  ["kick_ms2", "kick", "m/s²", 1, 2],
  ["shuffle_pp_ms2", "shuffle p-p", "m/s²", 1, 2],
  ["shuffle_freq_hz", "shuffle f (accel)", "Hz", 1, 2],
  ["max_jerk_ms3", "max jerk", "m/s³", 1, 1],
  ["clunk_ms2", "clunk", "m/s²", 1, 3],
  ["vdv_ms175", "VDV Wd", "m/s^1.75", 1, 2],
  ["settled_accel_ms2", "settled accel", "m/s²", 1, 2],
];
const PAGE = 12;

export function eventsTable(events, metrics, start) {
  const byIndex = new Map(metrics.events.map((m) => [m.event_index, m]));
  const cols = [
    { key: "index", label: "#", num: true, digits: 0 },
    { key: "kind", label: "kind", render: (e) => e.kind.replace("_", "-") },
    { key: "t_cross_s", label: "torque zero crossing", num: true, render: (e) => stamp(e.t_cross_s, start) },
    { key: "torque", label: "torque before → after (N m)", num: true, value: (e) => e.torque_after_nm,
      render: (e) => `${fmt(e.torque_before_nm)} → ${fmt(e.torque_after_nm)}` },
    { key: "motor_speed_rpm", label: "motor speed (rpm)", num: true, digits: 0 },
    { key: "pedal", label: "pedal before → after (%)", num: true, value: (e) => e.pedal_after_pct,
      render: (e) => (e.pedal_after_pct == null ? "-" : `${fmt(e.pedal_before_pct)} → ${fmt(e.pedal_after_pct)}`) },
    { key: "status", label: "analysed", value: (e) => e.exclusion || "", cls: "wrap",
      render: (e) => (e.included ? (byIndex.has(e.index) ? "yes" : e.error || "no metrics") : `excluded: ${e.exclusion}`) },
    { key: "tracking", label: "tracking", value: (e) => e.tracking?.verdict ?? "",
      render: (e) => (e.tracking ? badge(e.tracking.verdict) : "-") },
  ];
  return h("section", { class: "card offscreen-lazy" }, h("h2", {}, `Events (${events.count})`),
    h("div", { class: "scroll" }, sortableTable(cols, events.events, { id: "events-table" })));
}

// A metric the table does not name (a column added to the registry later) gets its key as label and
// the unit its suffix names (SI as the API sends it).
function metricSpec(name) {
  const known = METRICS.find((m) => m[0] === name);
  if (known) return known;
  const units = [["_rpm", "rpm", 1, 1], ["_hz", "Hz", 1, 2], ["_s", "s", 1, 3], ["_mps2", "m/s²", 1, 2],
    ["_ms2", "m/s²", 1, 2], ["_g", "g", 1, 3], ["_pct", "%", 1, 1], ["_nm", "N m", 1, 1], ["_mps3", "m/s³", 1, 2]];
  const u = units.find(([suffix]) => name.endsWith(suffix));
  const base = u ? name.slice(0, -u[0].length) : name;
  return [name, base.replaceAll("_", " "), u ? u[1] : "-", u ? u[2] : 1, u ? u[3] : 3];
}

const PARTS = [["measured", "meas"], ["simulated", "sim"], ["difference", "sim-meas"]];
const CHOICE = "lashscope.metricsColumns";
const DEFAULT_METRICS = ["fluctuation_rpm", "rise_height_rpm", "gap_open_time_s", "first_overshoot_rpm"];

// The metrics table: one column group per metric (measured, simulated, sim - meas), a chooser of the
// metrics and parts shown (kept in this browser), every metric the API sends (summary.metrics).
export function metricsTable(id, metrics) {
  const names = [...new Set([...METRICS.map((m) => m[0]), ...Object.keys(metrics.summary?.metrics || {})])]
    .filter((n) => metrics.events.some((m) => m.measured && n in m.measured) || METRICS.some((k) => k[0] === n));
  let choice;
  try {
    choice = JSON.parse(localStorage.getItem(CHOICE) || "null");
  } catch (_) {
    choice = null;
  }
  choice = choice || { metrics: DEFAULT_METRICS, parts: PARTS.map((p) => p[0]), errors: true };
  const holder = h("div", { class: "scroll" });
  const draw = () => {
    const cols = [
      { key: "event_index", label: "#", num: true, digits: 0 },
      { key: "kind", label: "kind", render: (m) => m.kind.replace("_", "-") },
      { key: "tracking", label: "tracking", value: (m) => m.tracking?.verdict ?? "",
        render: (m) => h("span", { title: (m.tracking?.reasons || []).join("; ") }, badge(m.tracking?.verdict ?? "unknown")) },
    ];
    for (const name of names.filter((n) => choice.metrics.includes(n))) {
      const [, label, unit, k, digits] = metricSpec(name);
      for (const [part, what] of PARTS.filter(([p]) => choice.parts.includes(p))) {
        cols.push({ key: `${name}.${part}`, label: what, group: `${label} (${unit})`, num: true, digits,
          title: `${label} ${what} (${unit}): click to sort`,
          value: (m) => (m[part]?.[name] == null ? null : m[part][name] * k) });
      }
    }
    if (choice.errors) {
      cols.push({ key: "rms_rpm", label: "RMS (rpm)", group: "aligned error", num: true, digits: 1 },
        { key: "nrmse", label: "NRMSE (-)", group: "aligned error", num: true, digits: 3 });
    }
    if (choice.feel !== false) {
      for (const [name, label, unit, k, digits] of FEEL) {
        for (const [part, what] of PARTS.filter(([p]) => p !== "difference" && choice.parts.includes(p))) {
          cols.push({ key: `accel.${name}.${part}`, label: what, group: `${label} (${unit})`, num: true, digits,
            value: (m) => { const v = m.drivability?.[part]?.[name]; return v == null ? null : v * k; } });
        }
      }
    }
    holder.replaceChildren(sortableTable(cols, metrics.events, { id: "metrics-table" }));
  };
  const save = () => {
    localStorage.setItem(CHOICE, JSON.stringify(choice));
    draw();
  };
  const toggle = (list, v, on) => (on ? [...new Set([...list, v])] : list.filter((x) => x !== v));
  const chooser = h("details", { class: "chooser", id: "metrics-chooser" }, h("summary", {}, "Columns"),
    h("div", {}, h("strong", {}, "metrics: "), names.map((n) => h("label", {}, h("input", { type: "checkbox",
      dataset: { metric: n }, checked: choice.metrics.includes(n),
      onchange: (e) => { choice.metrics = toggle(choice.metrics, n, e.target.checked); save(); } }), ` ${metricSpec(n)[1]}`))),
    h("div", {}, h("strong", {}, "values: "), PARTS.map(([p, what]) => h("label", {}, h("input", { type: "checkbox",
      dataset: { part: p }, checked: choice.parts.includes(p),
      onchange: (e) => { choice.parts = toggle(choice.parts, p, e.target.checked); save(); } }), ` ${what}`)),
    h("label", {}, h("input", { type: "checkbox", dataset: { part: "errors" }, checked: choice.errors,
      onchange: (e) => { choice.errors = e.target.checked; save(); } }), " aligned error"),
    h("label", {}, h("input", { type: "checkbox", dataset: { part: "feel" }, checked: choice.feel !== false,
      onchange: (e) => { choice.feel = e.target.checked; save(); } }), " drivability (acceleration)")));
  draw();
  return h("section", { class: "card offscreen-lazy" }, h("h2", {}, `Metrics per event (${metrics.events.length})`),
    h("div", { class: "toolbar" }, h("span", { class: "muted" }, "Click a column to sort. Speed metrics are taken on the motor speed detrended from the rigid-body trend; sim-meas is each event's own difference. Definitions: docs/metrics.md, " +
      "drivability (acceleration) columns: docs/drivability.md."),
      h("button", { id: "metrics-csv", onclick: () => download(`/analyses/${id}/metrics?format=csv`,
        `${id}-metrics.csv`, "text/csv") }, "CSV (every column)")),
    chooser, holder);
}

// The overlays follow the whole-log chart: card.focusWindow(t0, t1) shows the events whose crossing
// is in that window (null: every event); onShow(t0, t1) zooms the whole-log chart to one event.
export function eventOverlays(id, events, metrics, signal, onShow) {
  const byIndex = new Map(metrics.events.map((m) => [m.event_index, m]));
  const all = events.events.filter((e) => e.has_series);
  let shown = all;
  const focus = h("span", { class: "muted", id: "overlay-focus" });
  const grid = h("div", { class: "grid", id: "overlays" });
  const shared = h("input", { type: "checkbox", id: "shared-y" });
  const pager = h("span", { class: "muted", id: "overlay-page" });
  let page = 0;
  let pages = Math.max(1, Math.ceil(shown.length / PAGE));
  const go = (p) => {
    page = Math.max(0, Math.min(pages - 1, p));
    draw();
  };
  const card = h("section", { class: "card" },
    h("h2", {}, `Overlays of every event with a series (${all.length} of ${events.count})`),
    h("p", { class: "muted" }, "Measured and simulated motor speed with torque on time from the torque zero crossing; ",
      "markers: the crossing (0), measured loss of load (gap open), measured and simulated impact. Panel titles quote ",
      "the fluctuation peak-to-valley (rpm). Excluded events have no series; the events table says why. Zooming the ",
      "whole-log chart shows the events in its window here; \"in chart\" zooms it to an event."),
    h("div", { class: "toolbar" }, h("button", { onclick: () => go(page - 1) }, "◀ previous"), pager,
      h("button", { id: "overlay-next", onclick: () => go(page + 1) }, "next ▶"),
      h("label", {}, shared, " same rpm span on every panel of the page"), focus),
    grid);
  // Redrawn a moment after the last zoom (a drag, or a burst of pans, is one redraw of up to twelve
  // panels, off the zoom's own frame), and only when the events in the window changed.
  let focusTimer = null;
  card.focusWindow = (t0, t1) => {
    clearTimeout(focusTimer);
    focusTimer = setTimeout(() => {
      const next = t0 == null ? all : all.filter((e) => e.t_cross_s >= t0 && e.t_cross_s <= t1);
      focus.textContent = t0 == null ? "" : `· ${next.length} event(s) in the chart's window ${fmt(t0, 2)}-${fmt(t1, 2)} s`;
      grid.dataset.focus = t0 == null ? "" : `${t0},${t1}`;
      if (next.length === shown.length && next.every((e, i) => e === shown[i])) return;
      shown = next;
      pages = Math.max(1, Math.ceil(shown.length / PAGE));
      go(0);
    }, 250);
  };
  shared.addEventListener("change", () => draw());

  let drawn = 0;
  async function draw() {
    const mine = ++drawn;
    grid.dataset.ready = "0";
    const part = shown.slice(page * PAGE, (page + 1) * PAGE);
    pager.textContent = `events ${part.length ? part[0].index : "-"}-${part.length ? part[part.length - 1].index : "-"}, ` +
      `page ${page + 1} of ${pages}`;
    let series;
    try {
      series = await Promise.all(part.map((e) => api(`/analyses/${id}/speed?event=${e.index}&max_points=800`, { signal })));
    } catch (err) {
      grid.replaceChildren(errorBox(err));
      return;
    }
    await new Promise(requestAnimationFrame); // laid out: the panels can take their width from the grid
    if (mine !== drawn) return;
    let span = 0;
    for (const s of series) {
      const v = [...s.measured_rpm, ...s.simulated_rpm].filter((x) => x != null);
      if (v.length) span = Math.max(span, Math.max(...v) - Math.min(...v));
    }
    const cols = Math.max(1, Math.floor((grid.clientWidth + 12) / 452));
    const width = Math.max(400, Math.floor((grid.clientWidth - 12 * (cols - 1)) / cols) - 14);
    grid.replaceChildren();
    part.forEach((e, i) => grid.append(panel(id, e, byIndex.get(e.index), series[i], shared.checked ? span * 1.1 : null, width, onShow)));
    if (!part.length) grid.append(h("p", { class: "muted" }, "no event with a series in this window"));
    grid.dataset.panels = part.length;
    grid.dataset.shared = shared.checked;
    grid.dataset.page = page + 1;
    grid.dataset.ready = "1";
  }
  draw();
  return card;
}

function panel(id, e, m, s, span, width, onShow) {
  const box = h("div", { class: "chart" });
  const meas = m?.measured || {};
  const sim = m?.simulated || {};
  const t0 = e.t_cross_s; // the panel's zero: the torque zero crossing, as in the CLI's plots
  const title = `#${e.index} ${e.kind.replace("_", "-")} at ${e.t_cross_s.toFixed(2)} s`;
  const sub = m ? `fluctuation peak-valley: measured ${fmt(meas.fluctuation_rpm)} rpm, simulated ${fmt(sim.fluctuation_rpm)} rpm` +
    ` · ${m.tracking ? `tracking ${m.tracking.verdict}` : ""}` : (e.error || "no metrics for this event");
  const markers = [{ t: 0, color: "#666", label: "0", dash: true }];
  if (meas.t_gap_open_s != null) markers.push({ t: meas.t_gap_open_s - t0, color: COLORS.gap, label: "gap open" });
  if (meas.t_impact_s != null) markers.push({ t: meas.t_impact_s - t0, color: COLORS.measured, label: "impact", width: 2 });
  if (sim.t_impact_s != null) markers.push({ t: sim.t_impact_s - t0, color: COLORS.simulated, label: "sim impact", dash: true, width: 2 });
  const yRange = span ? (lo, hi) => [(lo + hi) / 2 - span / 2, (lo + hi) / 2 + span / 2] : undefined;
  const wrap = h("div", { class: "panel", dataset: { event: e.index } }, h("h3", {}, title), h("div", { class: "sub" }, sub), box);
  const u = speedChart(box, seriesData(s, undefined, t0), { width, height: 230, markers: () => markers, yRange,
    xLabel: "time from torque zero crossing (s)" });
  box.chart = u; // for scripts driving the page
  wrap.append(h("button", { onclick: async () => saveBlob(await chartPng(u, `${id} ${title}`),
    `${id}-event-${e.index}.png`) }, "PNG"),
  onShow ? h("button", { class: "in-chart", onclick: () => onShow(e.t_start_s, e.t_end_s) }, "in chart") : null);
  return wrap;
}
