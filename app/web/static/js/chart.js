// uPlot charts of the analysis: measured vs simulated motor speed (rpm, left axis) with torque
// (N m, right axis), pedal (%, its own axis) and any other decoded channel on an axis of its unit,
// vertical markers (events, gap open, impact, cursors) with labels that never overlap, PNG export.
/* global uPlot */

export const COLORS = {
  measured: "#1f5fbf", simulated: "#d62728", torque: "#2a9d3a", pedal: "#8a5fbf",
  tip_in: "#0b7285", tip_out: "#e07b00", // tip-in teal: not the torque's green excluded: "#9a9a9a", gap: "#7b2fbe", impact: "#111111",
};

// Columnar API series -> uPlot data (null stays null: uPlot leaves a gap). The simulated speed comes
// before the measured one so that the measured line is drawn over it: at whole-log zoom the two
// overlap almost everywhere and the measured one is what the log says.
// tShift: subtracted from every time (overlays on time from the crossing).
export function seriesData(s, pedal, tShift = 0) {
  const t = tShift ? s.t_s.map((x) => x - tShift) : s.t_s;
  const cols = [t, s.simulated_rpm, s.measured_rpm, s.torque_nm];
  if (pedal !== undefined) cols.push(pedal);
  return cols;
}

// Pedal samples (own time base) onto the speed times: the last pedal sample at or before each time.
export function holdOnto(t, pt, pv) {
  const out = new Array(t.length).fill(null);
  let j = 0;
  for (let i = 0; i < t.length; i++) {
    while (j + 1 < pt.length && pt[j + 1] <= t[i]) j++;
    if (pt.length && pt[j] <= t[i]) out[i] = pv[j];
  }
  return out;
}

// Labels of vertical markers laid out on rows so that none overlaps another: each label goes on the
// first row whose last label ends left of it (x positions and widths in canvas pixels).
export function labelRows(items, gap = 4) {
  const ends = [];
  return items.map(({ x, w }) => {
    let row = ends.findIndex((end) => end + gap <= x);
    if (row < 0) {
      row = ends.length;
      ends.push(0);
    }
    ends[row] = x + w;
    return row;
  });
}

function markerPlugin(getMarkers) {
  return {
    hooks: {
      draw: [(u) => {
        const ctx = u.ctx;
        const { left, top, width, height } = u.bbox;
        const [x0, x1] = [u.scales.x.min, u.scales.x.max];
        const dpr = devicePixelRatio;
        ctx.save();
        ctx.font = `${Math.round(10 * dpr)}px sans-serif`;
        const shown = getMarkers().filter((m) => m.t >= x0 && m.t <= x1)
          .map((m) => ({ m, x: Math.round(u.valToPos(m.t, "x", true)) })).sort((a, b) => a.x - b.x);
        for (const { m, x } of shown) {
          ctx.strokeStyle = m.color;
          ctx.lineWidth = dpr * (m.width || 1);
          ctx.setLineDash(m.dash ? [4 * dpr, 3 * dpr] : []);
          ctx.beginPath();
          ctx.moveTo(x, top);
          ctx.lineTo(x, top + height);
          ctx.stroke();
        }
        // labels beside their line, on as many rows as it takes for none to cover another; the rows
        // are counted on the element (data-label-rows) for tests
        const labelled = shown.filter((s) => s.m.label);
        const boxes = labelled.map(({ m, x }) => {
          const w = ctx.measureText(m.label).width + 2 * dpr;
          return { x: Math.min(x + 3 * dpr, left + width - w), w };
        });
        const rows = labelRows(boxes);
        labelled.forEach(({ m }, i) => {
          const yy = top + (11 + 11 * rows[i]) * dpr;
          ctx.fillStyle = "rgba(255,255,255,0.8)";
          ctx.fillRect(boxes[i].x - dpr, yy - 9 * dpr, boxes[i].w, 11 * dpr);
          ctx.fillStyle = m.color;
          ctx.fillText(m.label, boxes[i].x, yy);
        });
        u.root.parentElement.dataset.labelRows = rows.length ? Math.max(...rows) + 1 : 0;
        u.labelBoxes = boxes.map((b, i) => ({ ...b, row: rows[i] }));
        ctx.restore();
      }],
    },
  };
}

const EXTRA_COLORS = ["#8c564b", "#e377c2", "#17becf", "#bcbd22", "#7f7f7f", "#9467bd", "#ff7f0e", "#393b79", "#637939", "#843c39"];

// The scale a channel's unit is drawn on: units the chart has already (rpm, N m, %) share their axis.
export function unitScale(unit) {
  const u = (unit || "").replace(/\s|·/g, "").toLowerCase();
  if (u === "rpm" || u === "1/min") return "rpm";
  if (u === "nm") return "nm";
  if (u === "%") return "pct";
  return `u:${unit || "-"}`;
}

export function extraColor(i) {
  return EXTRA_COLORS[i % EXTRA_COLORS.length];
}

// The chart: options.pedal adds the pedal series (its own axis, %); options.extras adds decoded
// channels [{name, unit, color}] after them, each on the axis of its unit (a new axis per new unit);
// options.yRange(min, max) fixes the rpm range; options.onZoom(t0, t1) is called when the user zooms
// or pans the time axis; options.onClick(t, shift) on a click in the plot (not a drag).
export function speedChart(el, data, { width, height, markers = () => [], pedal = false, extras = [], yRange, onZoom,
  onClick, title, xLabel = "time since log start (s)", x } = {}) {
  // 1 px lines: the rows are min/max pairs, so a dense view is a zigzag of long vertical strokes, and
  // the canvas rasterises a 1 px stroke as a hairline but a 1.5 px one as a filled outline, which
  // measured 20x slower (30 vs 600 ms for 1700 zigzag rows on a loaded 2-core machine, headless
  // Chromium): the difference between a first paint inside and outside the 1 s target.
  const series = [
    { label: "t (s)", value: (u, v) => (v == null ? "-" : v.toFixed(3)) },
    { label: "simulated rpm", scale: "rpm", stroke: COLORS.simulated, width: 1 },
    { label: "measured rpm", scale: "rpm", stroke: COLORS.measured, width: 1 },
    { label: "torque N m", scale: "nm", stroke: COLORS.torque, width: 1 },
  ];
  const axes = [
    { label: xLabel },
    { scale: "rpm", label: "motor speed (rpm)" },
    { scale: "nm", side: 1, label: "torque (N m)", grid: { show: false } },
  ];
  const scales = {
    x: x ? { time: false, min: x[0], max: x[1] } : { time: false },
    rpm: yRange ? { range: (u, lo, hi) => yRange(lo, hi) } : {},
    nm: {},
    pct: { range: [0, 100] },
  };
  if (pedal) {
    series.push({ label: "pedal %", scale: "pct", stroke: COLORS.pedal, width: 1, dash: [5, 3] });
    axes.push({ scale: "pct", side: 1, label: "pedal (%)", grid: { show: false }, stroke: COLORS.pedal, size: 44 });
  }
  const axisOf = new Set(axes.map((a) => a.scale));
  let side = 0;
  for (const ch of extras) {
    const scale = unitScale(ch.unit);
    series.push({ label: `${ch.name} ${ch.unit || ""}`.trim(), scale, stroke: ch.color, width: 1, spanGaps: true });
    if (!axisOf.has(scale)) {
      axisOf.add(scale);
      scales[scale] = {};
      axes.push({ scale, side: side++ % 2 ? 1 : 3, label: `${ch.unit || "-"} (${ch.name})`, grid: { show: false },
        stroke: ch.color, size: 56 });
    }
  }
  let quiet = true; // until the first draw: uPlot's own initial scale is not a user's zoom
  const opts = {
    title, width, height, scales, axes, series,
    cursor: { drag: { x: true, y: false } },
    plugins: [markerPlugin(markers)],
    hooks: {
      ready: [(u) => {
        quiet = false;
        if (onClick) {
          let down = null;
          u.over.addEventListener("mousedown", (e) => { down = e.clientX; });
          u.over.addEventListener("mouseup", (e) => {
            if (down !== null && Math.abs(e.clientX - down) < 3) onClick(u.posToVal(e.offsetX, "x"), e.shiftKey);
            down = null;
          });
        }
      }],
      // the first draw's phases as performance marks, named by the element's id (bench/dashboard.py)
      drawClear: [() => {
        if (el.id && !el.dataset.draws) performance.mark(`chart:${el.id}:draw`);
      }],
      // what was drawn, on the element: tests and people's scripts can see that lines are on the canvas
      draw: [(u) => {
        if (el.id && !el.dataset.draws) performance.mark(`chart:${el.id}:drawn`);
        el.dataset.ySpan = u.scales.rpm.max - u.scales.rpm.min;
        el.dataset.draws = (Number(el.dataset.draws) || 0) + 1;
        el.dataset.series = u.series.length - 1;
        el.dataset.axes = u.axes.length;
        countInkAfterPaint(el, u);
      }],
      setScale: [(u, key) => {
        if (key === "x" && onZoom && !quiet) onZoom(u.scales.x.min, u.scales.x.max);
      }],
    },
  };
  const u = new uPlot(opts, data, el);
  // replace the data without reporting it as a zoom (keepX: stay in the user's window)
  u.replace = (d, keepX) => {
    quiet = true;
    try {
      u.setData(d, !keepX);
    } finally {
      quiet = false;
    }
  };
  return u;
}

// The value of data column k nearest to time t (the closest row with a value), or null.
export function valueAt(data, k, t) {
  const xs = data[0];
  let lo = 0;
  let hi = xs.length - 1;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (xs[mid] < t) lo = mid + 1;
    else hi = mid;
  }
  if (lo > 0 && Math.abs(xs[lo - 1] - t) <= Math.abs(xs[lo] - t)) lo -= 1;
  for (let d = 0; d < 2000; d++) {
    for (const i of [lo - d, lo + d]) {
      if (i >= 0 && i < xs.length && data[k][i] != null) return { t: xs[i], v: data[k][i] };
    }
  }
  return null;
}

// The chart as a PNG on a white background, with a title line above it.
export function chartPng(u, title) {
  const src = u.ctx.canvas;
  const pad = 28 * devicePixelRatio;
  const c = document.createElement("canvas");
  c.width = src.width;
  c.height = src.height + pad;
  const ctx = c.getContext("2d");
  ctx.fillStyle = "#fff";
  ctx.fillRect(0, 0, c.width, c.height);
  ctx.fillStyle = "#111";
  ctx.font = `${Math.round(13 * devicePixelRatio)}px sans-serif`;
  ctx.fillText(title, 8 * devicePixelRatio, 18 * devicePixelRatio);
  ctx.drawImage(src, 0, pad);
  return new Promise((resolve) => c.toBlob(resolve, "image/png"));
}

// data-inked after the frame is shown, once per burst of draws, and absent until the latest draw is
// counted: reading the canvas back (getImageData) took as long as the draw and the layout together
// (about 180 ms of a 1 s first paint on a loaded 2-core machine), so it stays off the paint.
function countInkAfterPaint(el, u) {
  delete el.dataset.inked;
  if (el.inkPending) return;
  el.inkPending = true;
  requestAnimationFrame(() => setTimeout(() => {
    el.inkPending = false;
    el.dataset.inked = inkedPixels(u);
    if (el.id && !el.dataset.inkedOnce) performance.mark(`chart:${el.id}:inked`);
    el.dataset.inkedOnce = "1";
  }, 0));
}

// How many pixels of the plot area carry the speed lines' colours (measured, simulated): > 0 only
// once data is drawn -- event markers, grid and axes use other colours. Shown on the chart element.
export function inkedPixels(u, colors = [COLORS.measured, COLORS.simulated]) {
  const rgb = colors.map((c) => [1, 3, 5].map((k) => parseInt(c.slice(k, k + 2), 16)));
  const { left, top, width, height } = u.bbox;
  const img = u.ctx.getImageData(left, top, Math.max(1, width), Math.max(1, height)).data;
  let n = 0;
  for (let i = 0; i < img.length; i += 4) {
    if (img[i + 3] < 200) continue;
    for (const [r, g, b] of rgb) {
      if (Math.abs(img[i] - r) + Math.abs(img[i + 1] - g) + Math.abs(img[i + 2] - b) < 60) {
        n++;
        break;
      }
    }
  }
  return n;
}

// A plain line chart on one y scale: data [x, ...ys]; series [{label, color, width, dash, points}];
// spans [{t0, t1, color, label}] shaded behind the lines; markers as speedChart's.
export function lineChart(el, data, { width, height, series, xLabel, yLabel, spans = [], markers = () => [], title } = {}) {
  const shade = {
    hooks: {
      drawClear: [(u) => {
        const { top, height: hh } = u.bbox;
        for (const s of spans) {
          if (s.t0 == null || s.t1 == null) continue;
          const a = u.valToPos(s.t0, "x", true);
          const b = u.valToPos(s.t1, "x", true);
          u.ctx.fillStyle = s.color || "rgba(0,0,0,0.08)";
          u.ctx.fillRect(Math.min(a, b), top, Math.abs(b - a), hh);
        }
      }],
    },
  };
  const opts = {
    title, width, height,
    scales: { x: { time: false } },
    axes: [{ label: xLabel }, { label: yLabel }],
    series: [{ label: xLabel, value: (u, v) => (v == null ? "-" : v.toFixed(3)) },
      ...series.map((s) => ({ label: s.label, stroke: s.color, width: s.width || 1, dash: s.dash,
        points: { show: !!s.points, size: 3, fill: s.color }, paths: s.points ? () => null : undefined }))],
    legend: { show: false }, // the page names the colours once, above the panels
    cursor: { drag: { x: true, y: false } },
    plugins: [shade, markerPlugin(markers)],
    hooks: { draw: [() => { el.dataset.draws = (Number(el.dataset.draws) || 0) + 1; }] },
  };
  return new uPlot(opts, data, el);
}
