// Analysis view: status until done, then the whole-log timeline (zoom and pan fetch finer data with
// max_points for the window shown), the events, the metrics table and the per-event overlays.
import { api, download, saveBlob } from "./api.js";
import { chartPng, COLORS, holdOnto, seriesData, speedChart } from "./chart.js";
import { eventOverlays, eventsTable, metricsTable } from "./events.js";
import { badge, errorBox, fmt, h, logStart, progressBar, sleep, stamp, utc } from "./util.js";

const MAX_POINTS_CAP = 4000;

export async function render(main, id) {
  const ctrl = new AbortController();
  const head = h("div", {});
  main.append(h("h1", {}, "Analysis ", h("code", {}, id)), head);
  let rec;
  for (;;) {
    rec = await api(`/analyses/${id}`, { signal: ctrl.signal });
    if (rec.status === "done" || rec.status === "failed" || ctrl.signal.aborted) break;
    head.replaceChildren(h("p", {}, badge(rec.status), ` ${rec.job.stage}`),
      progressBar(rec.progress, `${rec.job.stage}: ${Math.round(100 * rec.progress)} %`));
    await sleep(1000);
  }
  if (rec.status === "failed") {
    head.replaceChildren(badge("failed"), errorBox(new Error(`${rec.job.error.detail} [${rec.job.error.code}]`)));
    return () => ctrl.abort();
  }
  head.replaceChildren(h("p", { class: "muted" }, "loading results ..."));
  // First paint first: the chart needs one bounded series read (and the pedal channel's); the
  // events (markers), the metrics (summary, tables) and the log record are asked for once it is
  // drawn, so their parsing does not hold it up.
  const signalsP = api(`/analyses/${id}/signals`);
  const timeline = h("div", { id: "timeline", class: "chart" });
  const info = h("span", { class: "muted", id: "timeline-info" });
  const card = h("section", { class: "card" }, h("h2", {}, "Whole log: measured vs simulated motor speed, torque, pedal"),
    h("p", { class: "muted" }, "Drag across the chart to zoom; the server sends at most one row pair per pixel ",
      "for the window shown (max_points), so zooming in shows finer data. Vertical lines: events ",
      h("span", { style: `color:${COLORS.tip_in}` }, "tip-in"), ", ",
      h("span", { style: `color:${COLORS.tip_out}` }, "tip-out"), ", ",
      h("span", { style: `color:${COLORS.excluded}` }, "excluded (dashed)"), "."));
  main.append(card);
  let markers = [];
  let start = null;
  const width = Math.max(600, card.clientWidth - 40);
  const maxPoints = Math.min(MAX_POINTS_CAP, 2 * width);

  let pedalName; // known once the channel list has arrived
  async function fetchWindow(t0, t1) {
    const q = t0 === undefined ? "" : `&t0=${t0}&t1=${t1}`;
    const speedP = api(`/analyses/${id}/speed?max_points=${maxPoints}${q}`);
    if (pedalName === undefined) pedalName = Object.keys((await signalsP).signals).find((n) => n.startsWith("pedal")) || null;
    const [s, p] = await Promise.all([speedP,
      pedalName ? api(`/analyses/${id}/signals/${pedalName}?max_points=${maxPoints}${q}`) : null]);
    return { s, data: seriesData(s, p ? holdOnto(s.t_s, p.t_s, p[pedalName]) : undefined) };
  }

  const first = await fetchWindow();
  let chart;
  let seq = 0;
  let timer = null;
  const show = (s, t0, t1, count = true) => {
    timeline.dataset.points = s.points;
    timeline.dataset.sourcePoints = s.source_points;
    timeline.dataset.t0 = t0;
    timeline.dataset.t1 = t1;
    if (count) timeline.dataset.loads = (Number(timeline.dataset.loads) || 0) + 1;
    info.textContent = `${s.points} of ${s.source_points} rows in ${fmt(t0, 2)}-${fmt(t1, 2)} s` +
      (start ? ` · ${stamp(t0, start)}` : "");
  };
  const zoomTo = (t0, t1) => {
    clearTimeout(timer);
    // no delay: a drag is one zoom; several scale changes in one task (pan buttons) make one request
    timer = setTimeout(async () => {
      const mine = ++seq;
      try {
        const w = await fetchWindow(t0, t1);
        if (mine !== seq || ctrl.signal.aborted) return;
        chart.replace(w.data, true);
        show(w.s, t0, t1);
      } catch (err) {
        info.replaceChildren(errorBox(err));
      }
    }, 0);
  };
  chart = speedChart(timeline, first.data, { width, height: 380, markers: () => markers, pedal: !!pedalName,
    onZoom: zoomTo });
  timeline.chart = chart; // for scripts driving the page (bench/dashboard.py)
  const tStart = first.s.t_s[0];
  const tEnd = first.s.t_s[first.s.t_s.length - 1];
  show(first.s, tStart, tEnd);
  const setX = (a, b) => chart.setScale("x", { min: Math.max(tStart, a), max: Math.min(tEnd, b) });
  const span = () => chart.scales.x.max - chart.scales.x.min;
  card.append(h("div", { class: "toolbar" },
    h("button", { id: "full-view", onclick: async () => {
      seq++;
      const w = await fetchWindow();
      chart.replace(w.data, false);
      show(w.s, tStart, tEnd);
    } }, "Whole log"),
    h("button", { onclick: () => setX(chart.scales.x.min - span() / 2, chart.scales.x.max - span() / 2) }, "◀ pan"),
    h("button", { onclick: () => setX(chart.scales.x.min + span() / 2, chart.scales.x.max + span() / 2) }, "pan ▶"),
    h("button", { onclick: () => setX(chart.scales.x.min - span() / 2, chart.scales.x.max + span() / 2) }, "zoom out"),
    h("button", { id: "png-timeline", onclick: async () => saveBlob(await chartPng(chart,
      `${id}: ${fmt(chart.scales.x.min, 2)}-${fmt(chart.scales.x.max, 2)} s`), `${id}-timeline.png`) }, "PNG"),
    h("button", { onclick: () => download(`/analyses/${id}/speed?format=csv&max_points=0` +
      `&t0=${chart.scales.x.min}&t1=${chart.scales.x.max}`, `${id}-speed.csv`, "text/csv") }, "CSV of this window"),
    info), timeline);
  // Let the browser present the chart before the tables are built and laid out.
  await new Promise((resolve) => requestAnimationFrame(() => {
    timeline.dataset.paintedMs = performance.now().toFixed(0); // since navigation start (bench/dashboard.py)
    setTimeout(resolve, 0);
  }));

  const [log, events, metrics] = await Promise.all([api(`/logs/${rec.log_id}`).catch(() => null),
    api(`/analyses/${id}/events`), api(`/analyses/${id}/metrics`)]);
  start = log ? logStart(log.start_time) : null;
  markers = events.events.map((e) => ({ t: e.t_cross_s, color: e.included ? COLORS[e.kind] : COLORS.excluded,
    dash: !e.included, label: `${e.index}` }));
  chart.redraw(false, false);
  if (seq === 0) show(first.s, tStart, tEnd, false); // now with the absolute time of the log start
  head.replaceChildren(summary(rec, log, metrics, start, id, ctrl));
  main.append(eventsTable(events, metrics, start),
    metricsTable(id, metrics),
    eventOverlays(id, events, metrics, ctrl.signal));
  main.dataset.state = "ready";
  return () => {
    ctrl.abort();
    clearTimeout(timer);
  };
}

function summary(rec, log, metrics, start, id, ctrl) {
  const s = metrics.summary;
  const tracking = metrics.tracking || s.tracking || { verdict: "unknown", reasons: [] };
  const diagnose = h("button", { class: "primary", id: "diagnose", onclick: async () => {
    diagnose.disabled = true;
    try {
      const body = pick.value ? { candidates: [pick.value] } : {};
      const d = await api(`/analyses/${id}/diagnoses`, { method: "POST", json: body, signal: ctrl.signal });
      location.hash = `#/diagnosis/${d.id}`;
    } catch (err) {
      diagnose.after(errorBox(err));
      diagnose.disabled = false;
    }
  } }, "Diagnose the sim-to-real gap");
  const pick = h("select", { id: "diagnose-candidates", "aria-label": "candidate effects" },
    h("option", { value: "" }, "every candidate effect"));
  api("/effects").then((effects) => {
    for (const e of effects) pick.append(h("option", { value: e.id }, `only ${e.title}`));
  }).catch(() => pick.remove());
  return h("section", { class: "card", id: "summary" },
    h("dl", { class: "kv" },
      h("dt", {}, "log"), h("dd", {}, log ? `${log.filename} (${log.id})` : rec.log_id),
      h("dt", {}, "log start"), h("dd", {}, start ? `${utc(log.start_time)}${start.zoned ? "" : " (log clock, zone not recorded)"}` : "not recorded in the log"),
      h("dt", {}, "vehicle"), h("dd", {}, h("a", { href: "#/vehicles" }, `${rec.vehicle} v${rec.vehicle_version}`)),
      h("dt", {}, "events"), h("dd", {}, `${s.events} found: ${s.tip_in} tip-in, ${s.tip_out} tip-out; ` +
        `${s.included} included, ${s.with_metrics} with metrics`),
      h("dt", {}, "tracking"), h("dd", { id: "tracking" }, badge(tracking.verdict), " ",
        tracking.verdict === "good" ? "the simulation tracks this log" : (tracking.reasons || []).join("; ")),
      h("dt", {}, "torque-to-speed offset"), h("dd", {}, `${fmt(s.offset_ms, 1)} ms` + (s.offset_applied ? "" : " (not applied)")),
      h("dt", {}, "whole-log RMS error"), h("dd", {}, `${fmt(s.whole_rms_rpm, 1)} rpm (NRMSE ${fmt(s.whole_nrmse, 3)})`),
      h("dt", {}, "finished"), h("dd", {}, utc(rec.job.finished_at))),
    (metrics.notes || []).length ? h("div", { class: "note" }, metrics.notes.join(" ")) : null,
    h("div", { class: "toolbar" }, diagnose, pick));
}
