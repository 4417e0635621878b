// Live: the server's live sessions, start one, and a running session's motor speed and torque
// streaming over the session's server-sent events, with events appearing as they complete. On open
// (and so after a reload) the session's status and every event it has completed so far are read
// first (/live/sessions/<id>, /events); the stream then adds to them, one row per event index.
/* global uPlot */
import { api, streamEvents } from "./api.js";
import { COLORS, holdOnto, inkedPixels } from "./chart.js";
import { badge, errorBox, fmt, h } from "./util.js";

const WINDOW_S = 30;

export async function render(main, sessionId) {
  const ctrl = new AbortController();
  main.append(h("h1", {}, "Live"));
  if (sessionId) {
    await session(main, sessionId, ctrl.signal);
  } else {
    await sessions(main);
  }
  return () => ctrl.abort();
}

async function sessions(main) {
  const list = h("div", { id: "sessions" });
  const iface = h("input", { id: "live-interface", value: "tcp_loopback", size: 12 });
  const channel = h("input", { id: "live-channel", value: "127.0.0.1:29536", size: 18 });
  const vehicle = h("select", { id: "live-vehicle" }, h("option", { value: "" }, "(vehicle)"));
  const msg = h("span", {});
  api("/vehicles").then((vs) => vs.forEach((v) => vehicle.append(h("option", { value: v.name }, v.name))));
  const form = h("form", { class: "toolbar" }, "interface ", iface, " channel ", channel, " ", vehicle,
    h("button", { class: "primary", type: "submit" }, "Start session"), msg);
  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    try {
      const s = await api("/live/sessions", { method: "POST", json: { interface: iface.value,
        channel: channel.value || null, vehicle: vehicle.value || null } });
      location.hash = `#/live/${s.id}`;
    } catch (err) {
      msg.replaceChildren(errorBox(err));
    }
  });
  const all = await api("/live/sessions");
  list.replaceChildren(all.length ? h("table", { id: "session-table" },
    h("thead", {}, h("tr", {}, ["session", "state", "bus", "frames", "events", "started"].map((c) => h("th", {}, c)))),
    h("tbody", {}, all.map((s) => h("tr", {}, h("td", {}, h("a", { href: `#/live/${s.id}` }, s.id)), h("td", {}, badge(s.state)),
      h("td", {}, `${s.bus.interface} ${s.bus.channel ?? ""} (${s.bus.state})`), h("td", { class: "num" }, s.frames_received),
      h("td", { class: "num" }, s.events), h("td", {}, s.started_at || "-")))))
    : h("p", { class: "muted" }, "No live sessions on this server."));
  main.append(h("section", { class: "card" }, h("h2", {}, "Start a session"),
    h("p", { class: "muted" }, "Without CAN sockets: python -m app.live.loopback --port 29536, then replay a log onto it (README)."), form),
    h("section", { class: "card" }, h("h2", {}, "Sessions"), list));
}

async function session(main, id, signal) {
  const status = h("div", { id: "live-status" });
  const chartBox = h("div", { id: "live-chart", class: "chart" });
  const evBody = h("tbody", {});
  const stop = h("button", { class: "danger", onclick: async () => {
    try {
      const done = await api(`/live/sessions/${id}/stop`, { method: "POST" });
      status.append(h("p", {}, "stopped; ", done.log_id ? `log ${done.log_id}` : "no log",
        done.analysis_id ? [" · ", h("a", { href: `#/analysis/${done.analysis_id}` }, "its analysis")] : ""));
    } catch (err) {
      status.append(errorBox(err));
    }
  } }, "Stop and store");
  const card = h("section", { class: "card" }, h("h2", {}, `Session ${id}: motor speed and torque, last ${WINDOW_S} s`),
    h("div", { class: "toolbar" }, stop, status), chartBox);
  main.append(card, h("section", { class: "card" }, h("h2", {}, "Completed events"),
    h("table", { id: "live-events" }, h("thead", {}, h("tr", {}, ["#", "kind", "t (s)", "fluctuation peak-valley (rpm)",
      "rise height (rpm)", "shuffle frequency (Hz)", "analysed"].map((c) => h("th", {}, c)))), evBody)));
  const width = Math.max(600, card.clientWidth - 40);
  const u = new uPlot({ width, height: 340, scales: { x: { time: false }, rpm: {}, nm: {} },
    axes: [{ label: "time since session start (s)" }, { scale: "rpm", label: "motor speed (rpm)" },
      { scale: "nm", side: 1, label: "torque (N m)", grid: { show: false } }],
    series: [{ label: "t (s)" }, { label: "motor speed rpm", scale: "rpm", stroke: COLORS.measured, width: 1.5 },
      { label: "torque N m", scale: "nm", stroke: COLORS.torque, width: 1 }],
    hooks: { draw: [(chart) => { chartBox.dataset.inked = inkedPixels(chart); }] } }, [[], [], []], chartBox);
  const buf = { st: [], sv: [], tt: [], tv: [] };
  let frames = 0;
  let pending = false;
  const redraw = () => {
    pending = false;
    u.setData([buf.st, buf.sv, holdOnto(buf.st, buf.tt, buf.tv)]);
    chartBox.dataset.samples = buf.st.length;
    chartBox.dataset.updates = frames;
  };
  const trim = (t, v, now) => {
    let k = 0;
    while (k < t.length && t[k] < now - WINDOW_S) k++;
    if (k) {
      t.splice(0, k);
      v.splice(0, k);
    }
  };
  const onMessage = (kind, data) => {
    if (kind === "samples") {
      frames++;
      for (const [name, s] of Object.entries(data.channels)) {
        if (name.startsWith("motor_speed")) {
          buf.st.push(...s.t);
          buf.sv.push(...s.v);
        } else if (name.startsWith("motor_torque")) {
          buf.tt.push(...s.t);
          buf.tv.push(...s.v);
        }
      }
      const now = buf.st.length ? buf.st[buf.st.length - 1] : 0;
      trim(buf.st, buf.sv, now);
      trim(buf.tt, buf.tv, now);
      if (!pending) {
        pending = true;
        requestAnimationFrame(redraw);
      }
    } else if (kind === "event") {
      upsert(data);
    } else if (kind === "status") {
      showStatus(data);
    } else if (kind === "end") {
      status.append(" · stream ended");
    }
  };
  const rows = new Map(); // event index -> its row: the history and the stream may both carry an event
  const upsert = (data) => {
    // live metrics are the measured ones (no simulation until the stored log is analysed)
    const m = data.metrics || {};
    const row = h("tr", { dataset: { event: data.index } }, h("td", {}, data.index),
        h("td", {}, String(data.kind || "").replace("_", "-")),
        h("td", { class: "num" }, fmt(data.t_cross_s, 2)),
        h("td", { class: "num" }, fmt(m.fluctuation_rpm)),
        h("td", { class: "num" }, fmt(m.rise_height_rpm)),
        h("td", { class: "num" }, fmt(m.shuffle_freq_hz, 2)),
        h("td", {}, data.exclusion ? `excluded: ${data.exclusion}` : m.error || (data.provisional ? "provisional" : "yes")));
    const old = rows.get(data.index);
    if (old) old.replaceWith(row);
    else {
      const after = [...rows.keys()].filter((k) => k > data.index).sort((a, b) => a - b)[0]; // newest first
      if (after === undefined) evBody.prepend(row);
      else rows.get(after).after(row);
    }
    rows.set(data.index, row);
    evBody.dataset.count = rows.size;
  };
  const showStatus = (data) => {
    status.replaceChildren(badge(data.state), ` ${data.bus.interface} ${data.bus.channel ?? ""} · ${fmt(data.frames_per_s, 0)} frames/s · `,
      `${data.frames_received} frames · ${data.frames_dropped ?? 0} dropped · ${data.events} events`);
  };
  (async () => {
    try {
      await streamEvents(`/live/sessions/${id}/stream`, onMessage, signal);
    } catch (err) {
      if (!signal.aborted) status.append(errorBox(err));
    }
  })();
  try {
    const [st, history] = await Promise.all([api(`/live/sessions/${id}`, { signal }), api(`/live/sessions/${id}/events`, { signal })]);
    if (!status.childNodes.length) showStatus(st);
    history.events.forEach(upsert);
    evBody.dataset.history = history.count;
  } catch (err) {
    if (!signal.aborted) card.before(errorBox(err));
  }
  main.dataset.state = "ready";
}
