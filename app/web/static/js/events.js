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
    { key: "status", label: "analysed", value: (e) => e.exclusion || "",
      render: (e) => (e.included ? (byIndex.has(e.index) ? "yes" : e.error || "no metrics") : `excluded: ${e.exclusion}`) },
    { key: "tracking", label: "tracking", value: (e) => e.tracking?.verdict ?? "",
      render: (e) => (e.tracking ? badge(e.tracking.verdict) : "-") },
  ];
  return h("section", { class: "card offscreen-lazy" }, h("h2", {}, `Events (${events.count})`),
    h("div", { class: "scroll" }, sortableTable(cols, events.events, { id: "events-table" })));
}

export function metricsTable(id, metrics) {
  const cols = [
    { key: "event_index", label: "#", num: true, digits: 0 },
    { key: "kind", label: "kind", render: (m) => m.kind.replace("_", "-") },
    { key: "tracking", label: "tracking", value: (m) => m.tracking?.verdict ?? "",
      render: (m) => h("span", { title: (m.tracking?.reasons || []).join("; ") }, badge(m.tracking?.verdict ?? "unknown")) },
  ];
  for (const [name, label, unit, k, digits] of METRICS) {
    for (const [part, what] of [["measured", "meas"], ["simulated", "sim"], ["difference", "sim-meas"]]) {
      cols.push({ key: `${name}.${part}`, label: `${label} ${what} (${unit})`, num: true, digits,
        value: (m) => (m[part][name] == null ? null : m[part][name] * k) });
    }
  }
  cols.push({ key: "rms_rpm", label: "aligned RMS error (rpm)", num: true, digits: 1 },
    { key: "nrmse", label: "NRMSE (-)", num: true, digits: 3 });
  for (const [name, label, unit, k, digits] of FEEL) {
    for (const [part, what] of [["measured", "meas"], ["simulated", "sim"]]) {
      cols.push({ key: `accel.${name}.${part}`, label: `${label} ${what} (${unit})`, num: true, digits,
        value: (m) => { const v = m.drivability?.[part]?.[name]; return v == null ? null : v * k; } });
    }
  }
  return h("section", { class: "card offscreen-lazy" }, h("h2", {}, `Metrics per event (${metrics.events.length})`),
    h("div", { class: "toolbar" }, h("span", { class: "muted" }, "Click a column to sort. Speed metrics are taken on the motor speed detrended from the rigid-body trend; sim-meas is each event's own difference. Definitions: docs/metrics.md, " +
      "drivability (acceleration) columns: docs/drivability.md."),
      h("button", { id: "metrics-csv", onclick: () => download(`/analyses/${id}/metrics?format=csv`,
        `${id}-metrics.csv`, "text/csv") }, "CSV")),
    h("div", { class: "scroll" }, sortableTable(cols, metrics.events, { id: "metrics-table" })));
}

export function eventOverlays(id, events, metrics, signal) {
  const byIndex = new Map(metrics.events.map((m) => [m.event_index, m]));
  const shown = events.events.filter((e) => e.has_series);
  const grid = h("div", { class: "grid", id: "overlays" });
  const shared = h("input", { type: "checkbox", id: "shared-y" });
  const pager = h("span", { class: "muted", id: "overlay-page" });
  let page = 0;
  const pages = Math.max(1, Math.ceil(shown.length / PAGE));
  const go = (p) => {
    page = Math.max(0, Math.min(pages - 1, p));
    draw();
  };
  const card = h("section", { class: "card" },
    h("h2", {}, `Overlays of every event with a series (${shown.length} of ${events.count})`),
    h("p", { class: "muted" }, "Measured and simulated motor speed with torque; markers: torque zero crossing (0), ",
      "measured loss of load (gap open), measured and simulated impact. Panel titles quote the fluctuation ",
      "peak-to-valley (rpm). Excluded events have no series; the events table says why."),
    h("div", { class: "toolbar" }, h("button", { onclick: () => go(page - 1) }, "◀ previous"), pager,
      h("button", { id: "overlay-next", onclick: () => go(page + 1) }, "next ▶"),
      h("label", {}, shared, " same rpm span on every panel of the page")),
    grid);
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
    part.forEach((e, i) => grid.append(panel(id, e, byIndex.get(e.index), series[i], shared.checked ? span * 1.1 : null, width)));
    grid.dataset.panels = part.length;
    grid.dataset.shared = shared.checked;
    grid.dataset.page = page + 1;
    grid.dataset.ready = "1";
  }
  draw();
  return card;
}

function panel(id, e, m, s, span, width) {
  const box = h("div", { class: "chart" });
  const meas = m?.measured || {};
  const sim = m?.simulated || {};
  const title = `#${e.index} ${e.kind.replace("_", "-")} at ${e.t_cross_s.toFixed(2)} s`;
  const sub = m ? `fluctuation peak-valley: measured ${fmt(meas.fluctuation_rpm)} rpm, simulated ${fmt(sim.fluctuation_rpm)} rpm` +
    ` · ${m.tracking ? `tracking ${m.tracking.verdict}` : ""}` : (e.error || "no metrics for this event");
  const markers = [{ t: e.t_cross_s, color: "#666", label: "0", dash: true }];
  if (meas.t_gap_open_s != null) markers.push({ t: meas.t_gap_open_s, color: COLORS.gap, label: "gap open" });
  if (meas.t_impact_s != null) markers.push({ t: meas.t_impact_s, color: COLORS.measured, label: "impact", width: 2 });
  if (sim.t_impact_s != null) markers.push({ t: sim.t_impact_s, color: COLORS.simulated, label: "sim impact", dash: true, width: 2 });
  const yRange = span ? (lo, hi) => [(lo + hi) / 2 - span / 2, (lo + hi) / 2 + span / 2] : undefined;
  const wrap = h("div", { class: "panel", dataset: { event: e.index } }, h("h3", {}, title), h("div", { class: "sub" }, sub), box);
  const u = speedChart(box, seriesData(s), { width, height: 230, markers: () => markers, yRange,
    xLabel: "time since log start (s)" });
  wrap.append(h("button", { onclick: async () => saveBlob(await chartPng(u, `${id} ${title}`),
    `${id}-event-${e.index}.png`) }, "PNG"));
  return wrap;
}
