// Analysis view: status until done, then the whole-log timeline (zoom and pan fetch finer data with
// max_points for the window shown), the events, the metrics table and the per-event overlays.
import { answer, api, download, saveBlob } from "./api.js";
import { chartPng, COLORS, holdOnto, seriesData, speedChart } from "./chart.js";
import { eventOverlays, eventsTable, metricsTable } from "./events.js";
import { badge, errorBox, fmt, h, logStart, progressBar, sleep, stamp, utc } from "./util.js";

const MAX_POINTS_CAP = 4000;

export async function render(main, id) {
  performance.mark("analysis:render");
  const ctrl = new AbortController();
  const head = h("div", {});
  const timeline = h("div", { id: "timeline", class: "chart" });
  const info = h("span", { class: "muted", id: "timeline-info" });
  // laid out (for its width) but not shown until the analysis is done and the chart drawn
  const card = h("section", { class: "card", style: "visibility:hidden" },
    h("h2", {}, "Whole log: measured vs simulated motor speed, torque, pedal"),
    h("p", { class: "muted" }, "Drag across the chart to zoom; the server sends at most one row pair per pixel ",
      "for the window shown (max_points), so zooming in shows finer data. Vertical lines: events ",
      h("span", { style: `color:${COLORS.tip_in}` }, "tip-in"), ", ",
      h("span", { style: `color:${COLORS.tip_out}` }, "tip-out"), ", ",
      h("span", { style: `color:${COLORS.excluded}` }, "excluded (dashed)"), "."));
  main.append(h("h1", {}, "Analysis ", h("code", {}, id)), head, card);
  const width = Math.max(600, card.clientWidth - 40);
  performance.mark("analysis:layout");
  // First paint: the chart's reads (channel list, whole-log rows, pedal rows) go out with the status
  // read, not after it, and on a fresh load of this page before the modules run (early.js, inlined
  // in the page). While the analysis still runs they answer 409 analysis_not_ready; then they are
  // dropped and asked again once it is done.
  const pre = window.lashscopeEarly?.id === id ? window.lashscopeEarly : null;
  window.lashscopeEarly = null; // once: coming back to the page reads afresh
  const maxPoints = pre ? pre.maxPoints : Math.min(MAX_POINTS_CAP, 2 * width);
  let pedalName; // known once the channel list has arrived
  const pedalRows = (q) => (pedalName ? api(`/analyses/${id}/signals/${pedalName}?max_points=${maxPoints}${q}`) : null);
  const early = (f) => {
    const reads = { record: f.record.then(answer), speed: f.speed.then(answer), pedal: f.pedal.then((p) => {
      pedalName = p ? p.name : null;
      return p ? p.rows.then(answer) : null;
    }) };
    for (const p of Object.values(reads)) p.catch(() => {}); // settled later, or replaced
    return reads;
  };
  let reads = early(pre || window.lashscopeFirstReads(id, maxPoints));
  let rec;
  for (let polls = 0; ; polls++) {
    rec = polls ? await api(`/analyses/${id}`, { signal: ctrl.signal }) : await reads.record;
    if (rec.status === "done" || rec.status === "failed" || ctrl.signal.aborted) {
      if (polls > 0) reads = early(window.lashscopeFirstReads(id, maxPoints)); // the first were made too early
      break;
    }
    head.replaceChildren(h("p", {}, badge(rec.status), ` ${rec.job.stage}`),
      progressBar(rec.progress, `${rec.job.stage}: ${Math.round(100 * rec.progress)} %`));
    await sleep(1000);
  }
  if (rec.status === "failed") {
    card.remove();
    head.replaceChildren(badge("failed"), errorBox(new Error(`${rec.job.error.detail} [${rec.job.error.code}]`)));
    return () => ctrl.abort();
  }
  performance.mark("analysis:record"); // the marks time the first paint (bench/dashboard.py)
  head.replaceChildren(h("p", { class: "muted" }, "loading results ..."));
  // The events (markers), the metrics (summary, tables) and the log record are asked for once the
  // chart is drawn, so their parsing does not hold it up.
  let markers = [];
  let start = null;

  // the rows of a window (t0, t1 s; the whole log when undefined), or of the early reads
  async function fetchWindow(t0, t1, first) {
    const q = t0 === undefined ? "" : `&t0=${t0}&t1=${t1}`;
    const [s, p] = await Promise.all(first ? [first.speed, first.pedal]
      : [api(`/analyses/${id}/speed?max_points=${maxPoints}${q}`), pedalRows(q)]);
    return { s, data: seriesData(s, p ? holdOnto(s.t_s, p.t_s, p[pedalName]) : undefined) };
  }

  const first = await fetchWindow(undefined, undefined, reads);
  performance.mark("analysis:series");
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
  card.style.visibility = "";
  performance.mark("analysis:drawn");
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
    s.read && s.read.damaged ? h("div", { class: "note", id: "read-report" },
      h("strong", {}, s.read.truncated ? "truncated log" : "damaged log"), `: ${s.read.note}`) : null,
    (s.findings || []).length ? h("div", { class: "note", id: "findings" },
      ...s.findings.map((f) => h("p", {}, h("strong", {}, f.code), `: ${f.message}`))) : null,
    (metrics.notes || []).length ? h("div", { class: "note" }, metrics.notes.join(" ")) : null,
    h("div", { class: "toolbar" }, diagnose, pick));
}
