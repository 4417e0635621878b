/* global uPlot */
// Analysis view: status until done, then the whole-log timeline (zoom and pan fetch finer data with
// max_points for the window shown) with any decoded channel added from the channel browser, two
// cursors with a delta readout, the events, the metrics table and the per-event overlays, which
// follow the timeline's zoom. #/analysis/<id>/ch=<name>,<name> opens with those channels plotted.
import { answer, api, download, saveBlob } from "./api.js";
import { chartPng, COLORS, extraColor, holdOnto, seriesData, speedChart, valueAt } from "./chart.js";
import { eventOverlays, eventsTable, metricsTable } from "./events.js";
import { badge, errorBox, etaText, fmt, h, logStart, progressBar, sleep, stamp, utc } from "./util.js";

const MAX_POINTS_CAP = 4000;

export async function render(main, id, extra = "") {
  performance.mark("analysis:render");
  const ctrl = new AbortController();
  const head = h("div", {});
  const timeline = h("div", { id: "timeline", class: "chart" });
  const info = h("span", { class: "muted", id: "timeline-info" });
  // laid out (for its width) but not shown until the analysis is done and the chart drawn
  const card = h("section", { class: "card", style: "visibility:hidden" },
    h("h2", {}, "Whole log: measured vs simulated motor speed, torque, pedal, any channel"),
    h("p", { class: "muted" }, "Drag across the chart to zoom; the server sends at most one row pair per pixel ",
      "for the window shown (max_points), so zooming in shows finer data. Click: cursor A, shift+click: cursor B. ",
      "Vertical lines: events ",
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
    const reads = { record: f.record.then(answer), speed: f.speed.then(answer), signals: f.signals.then(answer), pedal: f.pedal.then((p) => {
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
      progressBar(rec.progress, `${rec.job.stage}: ${Math.round(100 * rec.progress)} %${etaText(rec.job.eta_s)}`));
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

  // decoded channels on the chart beyond speed, torque and pedal: name -> {unit, color, rows of the window}
  const extras = new Map();
  const channelRows = (name, q) => api(`/analyses/${id}/signals/${encodeURIComponent(name)}?max_points=${maxPoints}${q}`);
  // the speed rows with the pedal held onto their times, then each channel's own rows joined on one time axis
  const build = (s, p) => {
    const base = seriesData(s, p ? holdOnto(s.t_s, p.t_s, p[pedalName]) : undefined);
    if (!extras.size) return base;
    return uPlot.join([base, ...[...extras].map(([name, c]) => [c.rows.t_s, c.rows[name]])]);
  };
  // the rows of a window (t0, t1 s; the whole log when undefined), or of the early reads
  async function fetchWindow(t0, t1, first) {
    const q = t0 === undefined ? "" : `&t0=${t0}&t1=${t1}`;
    const names = [...extras.keys()];
    const [s, p, ...chs] = await Promise.all(first ? [first.speed, first.pedal]
      : [api(`/analyses/${id}/speed?max_points=${maxPoints}${q}`), pedalRows(q), ...names.map((n) => channelRows(n, q))]);
    names.forEach((n, i) => { if (chs[i] && extras.has(n)) extras.get(n).rows = chs[i]; });
    return { s, p, data: build(s, p) };
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
  let overlays = null; // the per-event overlays, which follow the timeline's window once they exist
  let last = first; // the speed and pedal rows of the window shown
  const cursors = { A: null, B: null };
  const readout = h("div", { class: "readout", id: "cursor-readout" }, "no cursor: click the chart (A), shift+click (B)");
  const allMarkers = () => [...markers, ...Object.entries(cursors).filter(([, t]) => t != null)
    .map(([k, t]) => ({ t, color: "#000", label: k, width: 1.5 }))];
  const zoomTo = (t0, t1) => {
    clearTimeout(timer);
    // no delay: a drag is one zoom; several scale changes in one task (pan buttons) make one request
    timer = setTimeout(async () => {
      const mine = ++seq;
      try {
        const w = await fetchWindow(t0, t1);
        if (mine !== seq || ctrl.signal.aborted) return;
        last = w;
        chart.replace(w.data, true);
        show(w.s, t0, t1);
        if (overlays) overlays.focusWindow(t0, t1);
        updateReadout();
      } catch (err) {
        info.replaceChildren(errorBox(err));
      }
    }, 0);
  };
  const setCursor = (t, shift) => {
    cursors[shift ? "B" : "A"] = t;
    chart.redraw(false, false);
    updateReadout();
  };
  const makeChart = (data, xWindow) => speedChart(timeline, data, { width, height: 380, markers: allMarkers,
    pedal: !!pedalName, extras: [...extras].map(([name, c]) => ({ name, unit: c.unit, color: c.color })),
    onZoom: zoomTo, onClick: setCursor, x: xWindow });
  chart = makeChart(first.data);
  timeline.chart = chart; // for scripts driving the page (bench/dashboard.py)
  card.style.visibility = "";
  performance.mark("analysis:drawn");
  const tStart = first.s.t_s[0];
  const tEnd = first.s.t_s[first.s.t_s.length - 1];
  show(first.s, tStart, tEnd);

  // Each series' value at the cursors, and B - A: time and every value, in the series' units.
  function updateReadout() {
    const { A, B } = cursors;
    if (A == null && B == null) return;
    const rows = [];
    const col = (label, a, b, d) => `${label.padEnd(28)} ${a.padStart(12)} ${b.padStart(12)} ${d.padStart(12)}`;
    rows.push(col("", "A", "B", "B - A"));
    const f = (v, k = 3) => (v == null ? "-" : Number(v).toFixed(k));
    rows.push(col("time (s)", f(A), f(B), A != null && B != null ? f(B - A) : "-"));
    chart.series.forEach((sr, k) => {
      if (k === 0) return;
      const va = A != null ? valueAt(chart.data, k, A) : null;
      const vb = B != null ? valueAt(chart.data, k, B) : null;
      rows.push(col(sr.label, f(va?.v, 2), f(vb?.v, 2), va && vb ? f(vb.v - va.v, 2) : "-"));
    });
    readout.textContent = rows.join("\n");
    readout.dataset.a = A ?? "";
    readout.dataset.b = B ?? "";
  }

  // The channel browser: every decoded channel, searchable; a tick adds it to the chart on its unit's axis.
  const channelStatus = h("div", { id: "channel-status" });
  const search = h("input", { type: "search", id: "channel-search", placeholder: "search channels (name or unit)",
    "aria-label": "search channels" });
  const list = h("div", { class: "channels", id: "channel-list" });
  const browser = h("details", { id: "channel-browser", open: true }, h("summary", {}, "Channels of this log"),
    h("div", { class: "toolbar" }, search, channelStatus), list);
  let signals = {};
  const setHash = () => {
    const names = [...extras.keys()];
    history.replaceState(null, "", `#/analysis/${encodeURIComponent(id)}${names.length ? `/ch=${names.map(encodeURIComponent).join(",")}` : ""}`);
  };
  async function redrawWithChannels(name) {
    const xWindow = [chart.scales.x.min, chart.scales.x.max];
    const whole = xWindow[0] <= tStart && xWindow[1] >= tEnd;
    const q = whole ? "" : `&t0=${xWindow[0]}&t1=${xWindow[1]}`;
    if (name && extras.has(name) && !extras.get(name).rows) extras.get(name).rows = await channelRows(name, q);
    chart.destroy();
    timeline.replaceChildren();
    delete timeline.dataset.draws;
    chart = makeChart(build(last.s, last.p), whole ? undefined : xWindow);
    timeline.chart = chart;
    updateReadout();
  }
  async function addChannel(name) {
    if (extras.has(name)) return;
    performance.mark(`channel:${name}:asked`);
    const t0 = performance.now();
    extras.set(name, { unit: signals[name].unit, color: extraColor(extras.size), rows: null });
    try {
      await redrawWithChannels(name);
    } catch (err) {
      extras.delete(name);
      channelStatus.replaceChildren(errorBox(err));
      return;
    }
    await new Promise(requestAnimationFrame);
    timeline.dataset.channelMs = (performance.now() - t0).toFixed(0);
    performance.mark(`channel:${name}:drawn`);
    channelStatus.replaceChildren(h("span", { class: "muted" }, `${name} added in ${timeline.dataset.channelMs} ms`));
    setHash();
  }
  async function removeChannel(name) {
    extras.delete(name);
    [...extras.values()].forEach((c, i) => { c.color = extraColor(i); });
    await redrawWithChannels();
    setHash();
  }
  const drawList = () => {
    const q = search.value.trim().toLowerCase();
    const names = Object.keys(signals).sort().filter((n) => !q || n.toLowerCase().includes(q) ||
      (signals[n].unit || "").toLowerCase().includes(q));
    list.replaceChildren(...names.map((n) => {
      const box = h("input", { type: "checkbox", dataset: { channel: n }, checked: extras.has(n) || n === pedalName,
        disabled: n === pedalName, onchange: () => (box.checked ? addChannel(n) : removeChannel(n)) });
      return h("label", { title: `${signals[n].samples} samples, ${fmt(signals[n].t_start_s, 1)}-${fmt(signals[n].t_end_s, 1)} s` },
        box, ` ${n} `, h("span", { class: "muted" }, `(${signals[n].unit || "-"})`));
    }));
    list.dataset.shown = names.length;
    if (!names.length) list.append(h("span", { class: "muted" }, `no channel matches "${search.value}"`));
  };
  search.addEventListener("input", drawList);
  const setX = (a, b) => chart.setScale("x", { min: Math.max(tStart, a), max: Math.min(tEnd, b) });
  const span = () => chart.scales.x.max - chart.scales.x.min;
  card.append(h("div", { class: "toolbar" },
    h("button", { id: "full-view", onclick: async () => {
      seq++;
      const w = await fetchWindow();
      last = w;
      chart.replace(w.data, false);
      show(w.s, tStart, tEnd);
      if (overlays) overlays.focusWindow(null);
    } }, "Whole log"),
    h("button", { onclick: () => setX(chart.scales.x.min - span() / 2, chart.scales.x.max - span() / 2) }, "◀ pan"),
    h("button", { onclick: () => setX(chart.scales.x.min + span() / 2, chart.scales.x.max + span() / 2) }, "pan ▶"),
    h("button", { onclick: () => setX(chart.scales.x.min - span() / 2, chart.scales.x.max + span() / 2) }, "zoom out"),
    h("button", { id: "png-timeline", onclick: async () => saveBlob(await chartPng(chart,
      `${id}: ${fmt(chart.scales.x.min, 2)}-${fmt(chart.scales.x.max, 2)} s`), `${id}-timeline.png`) }, "PNG"),
    h("button", { onclick: () => download(`/analyses/${id}/speed?format=csv&max_points=0` +
      `&t0=${chart.scales.x.min}&t1=${chart.scales.x.max}`, `${id}-speed.csv`, "text/csv") }, "CSV of this window"),
    h("button", { id: "clear-cursors", onclick: () => {
      cursors.A = null;
      cursors.B = null;
      readout.textContent = "no cursor: click the chart (A), shift+click (B)";
      chart.redraw(false, false);
    } }, "clear cursors"),
    info), timeline, readout, browser);
  // Let the browser present the chart before the tables are built and laid out.
  await new Promise((resolve) => requestAnimationFrame(() => {
    timeline.dataset.paintedMs = performance.now().toFixed(0); // since navigation start (bench/dashboard.py)
    setTimeout(resolve, 0);
  }));

  const [log, events, metrics, sig] = await Promise.all([api(`/logs/${rec.log_id}`).catch(() => null),
    api(`/analyses/${id}/events`), api(`/analyses/${id}/metrics`),
    reads.signals.catch((err) => ({ error: err }))]);
  if (sig.error) channelStatus.replaceChildren(errorBox(sig.error));
  else {
    signals = sig.signals;
    drawList();
    // channels named in the address: each one plotted, or a message naming the one the log does not have
    const asked = (/^ch=(.*)$/.exec(extra) || [])[1];
    const missing = [];
    for (const n of asked ? asked.split(",").map(decodeURIComponent).filter(Boolean) : []) {
      if (n in signals) await addChannel(n);
      else missing.push(n);
    }
    drawList();
    if (missing.length) {
      channelStatus.replaceChildren(errorBox(new Error(`channel${missing.length > 1 ? "s" : ""} ${missing.join(", ")} ` +
        `not in this log's decoded channels (${Object.keys(signals).length} channels: search the list) [signal_not_found]`)));
    }
  }
  start = log ? logStart(log.start_time) : null;
  markers = events.events.map((e) => ({ t: e.t_cross_s, color: e.included ? COLORS[e.kind] : COLORS.excluded,
    dash: !e.included, label: `${e.index}` }));
  chart.redraw(false, false);
  if (seq === 0) show(first.s, tStart, tEnd, false); // now with the absolute time of the log start
  head.replaceChildren(summary(rec, log, metrics, start, id, ctrl));
  overlays = eventOverlays(id, events, metrics, ctrl.signal, (t0, t1) => setX(t0, t1));
  main.append(eventsTable(events, metrics, start),
    metricsTable(id, metrics),
    overlays);
  // loaded once the chart is up: its module is not on the first paint's path
  const { toleranceCard } = await import("./tolerance.js");
  main.append(toleranceCard(id, rec, ctrl.signal));
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
