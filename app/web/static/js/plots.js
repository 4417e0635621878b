// Small SVG charts for summaries (grouped bars, intervals, a band with points): every mark is an
// element with its numbers in data-* attributes and a <title> tooltip, so people's scripts and the
// browser tests can read what is drawn. Line charts of time series are uPlot's (chart.js).
import { fmt, svg } from "./util.js";

const FONT = 11;

function niceTicks(lo, hi, n = 5) {
  if (!(hi > lo)) return [lo];
  const step0 = (hi - lo) / n;
  const mag = 10 ** Math.floor(Math.log10(step0));
  const step = [1, 2, 2.5, 5, 10].map((k) => k * mag).find((s) => s >= step0) || step0;
  const out = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + 1e-9 * step; v += step) out.push(+v.toPrecision(12));
  return out;
}

function logTicks(lo, hi) {
  const out = [];
  for (let e = Math.floor(Math.log10(lo)); e <= Math.ceil(Math.log10(hi)); e++) {
    for (const k of [1, 3]) {
      const v = k * 10 ** e;
      if (v >= lo * 0.999 && v <= hi * 1.001) out.push(v);
    }
  }
  return out;
}

function tickLabel(v) {
  const a = Math.abs(v);
  return a >= 1000 || (a > 0 && a < 0.01) ? v.toPrecision(2) : String(+v.toPrecision(3));
}

// Grouped vertical bars: categories along x, one bar per group. groups: [{label, color, values}];
// log: a log10 y axis; ref: a dashed horizontal line {value, label}; yLabel with its unit.
export function barChart({ id, categories, groups, yLabel, log = false, ref = null, width = 560, height = 260 }) {
  const m = { l: 58, r: 12, t: 26, b: 46 };
  const all = groups.flatMap((g) => g.values).filter((v) => v != null && Number.isFinite(v) && (!log || v > 0));
  if (ref) all.push(ref.value);
  let lo = log ? Math.min(...all) / 1.5 : 0;
  let hi = Math.max(...all, log ? 1e-9 : 0) * (log ? 1.5 : 1.1);
  if (!all.length) [lo, hi] = [log ? 0.1 : 0, 1];
  if (!(hi > lo)) hi = lo + 1;
  const pw = width - m.l - m.r;
  const ph = height - m.t - m.b;
  const y = (v) => m.t + ph - (log ? (Math.log10(v) - Math.log10(lo)) / (Math.log10(hi) - Math.log10(lo))
    : (v - lo) / (hi - lo)) * ph;
  const root = svg("svg", { id, class: "plot", width, height, viewBox: `0 0 ${width} ${height}`, role: "img" });
  for (const t of log ? logTicks(lo, hi) : niceTicks(lo, hi)) {
    root.append(svg("line", { x1: m.l, x2: m.l + pw, y1: y(t), y2: y(t), class: "grid" }),
      svg("text", { x: m.l - 4, y: y(t) + 4, "text-anchor": "end", "font-size": FONT }, tickLabel(t)));
  }
  root.append(svg("text", { x: 12, y: m.t + ph / 2, transform: `rotate(-90 12 ${m.t + ph / 2})`, "text-anchor": "middle",
    "font-size": FONT }, yLabel));
  const slot = pw / categories.length;
  const bw = Math.min(28, (slot * 0.8) / groups.length);
  categories.forEach((c, i) => {
    const x0 = m.l + i * slot + (slot - bw * groups.length) / 2;
    groups.forEach((g, k) => {
      const v = g.values[i];
      if (v == null || !Number.isFinite(v) || (log && v <= 0)) return;
      const top = y(Math.min(Math.max(v, lo), hi));
      root.append(svg("rect", { x: x0 + k * bw, y: top, width: bw - 1, height: Math.max(0.5, m.t + ph - top),
        fill: g.color, class: "bar", dataset: { group: g.label, category: c, value: v } },
      svg("title", {}, `${c}, ${g.label}: ${tickLabel(v)}`)));
    });
    root.append(svg("text", { x: m.l + (i + 0.5) * slot, y: m.t + ph + 14, "text-anchor": "middle", "font-size": FONT },
      String(c).replaceAll("_", " ")));
  });
  if (ref && ref.value > lo && ref.value < hi) {
    root.append(svg("line", { x1: m.l, x2: m.l + pw, y1: y(ref.value), y2: y(ref.value), class: "ref" }),
      svg("text", { x: m.l + pw - 2, y: y(ref.value) - 3, "text-anchor": "end", "font-size": FONT }, ref.label));
  }
  root.append(legend(groups, m.l, 14));
  root.append(svg("line", { x1: m.l, x2: m.l, y1: m.t, y2: m.t + ph, class: "axis" }),
    svg("line", { x1: m.l, x2: m.l + pw, y1: m.t + ph, y2: m.t + ph, class: "axis" }));
  return root;
}

function legend(groups, x, yy) {
  const g = svg("g", { class: "legend" });
  let at = x;
  for (const grp of groups) {
    g.append(svg("rect", { x: at, y: yy - 9, width: 10, height: 10, fill: grp.color }),
      svg("text", { x: at + 14, y: yy, "font-size": FONT }, grp.label));
    at += 24 + 6.5 * grp.label.length;
  }
  return g;
}

// Horizontal intervals: one row per item {label, value, lo, hi, color, note}, a zero line, the x axis
// in `unit`. Values are drawn as dots, intervals as whiskers.
export function intervalChart({ id, rows, xLabel, width = 640, rowHeight = 24, zero = 0 }) {
  const labelW = Math.min(260, 12 + 6.6 * Math.max(8, ...rows.map((r) => r.label.length)));
  const m = { l: labelW, r: 16, t: 8, b: 40 };
  const height = m.t + m.b + rowHeight * Math.max(1, rows.length);
  const vals = rows.flatMap((r) => [r.lo, r.hi, r.value]).filter((v) => v != null && Number.isFinite(v));
  let lo = Math.min(zero, ...vals);
  let hi = Math.max(zero, ...vals);
  const pad = (hi - lo) * 0.05 || 1;
  lo -= pad;
  hi += pad;
  const pw = width - m.l - m.r;
  const x = (v) => m.l + ((v - lo) / (hi - lo)) * pw;
  const root = svg("svg", { id, class: "plot", width, height, viewBox: `0 0 ${width} ${height}`, role: "img" });
  const yAxis = m.t + rowHeight * rows.length;
  for (const t of niceTicks(lo, hi)) {
    root.append(svg("line", { x1: x(t), x2: x(t), y1: m.t, y2: yAxis, class: "grid" }),
      svg("text", { x: x(t), y: yAxis + 14, "text-anchor": "middle", "font-size": FONT }, tickLabel(t)));
  }
  root.append(svg("line", { x1: x(zero), x2: x(zero), y1: m.t, y2: yAxis, class: "ref" }),
    svg("text", { x: m.l + pw / 2, y: yAxis + 32, "text-anchor": "middle", "font-size": FONT }, xLabel));
  rows.forEach((r, i) => {
    const cy = m.t + rowHeight * (i + 0.5);
    const g = svg("g", { class: "interval", dataset: { label: r.label, value: r.value ?? "", lo: r.lo ?? "", hi: r.hi ?? "" } },
      svg("title", {}, `${r.label}: ${fmt(r.value, 3)} [${fmt(r.lo, 3)}, ${fmt(r.hi, 3)}]${r.note ? ` · ${r.note}` : ""}`));
    g.append(svg("text", { x: m.l - 6, y: cy + 4, "text-anchor": "end", "font-size": FONT,
      "font-weight": r.strong ? "bold" : null }, r.label));
    if (r.lo != null && r.hi != null && Number.isFinite(r.lo) && Number.isFinite(r.hi)) {
      g.append(svg("line", { x1: x(r.lo), x2: x(r.hi), y1: cy, y2: cy, stroke: r.color || "#333", "stroke-width": 2 }),
        svg("line", { x1: x(r.lo), x2: x(r.lo), y1: cy - 5, y2: cy + 5, stroke: r.color || "#333" }),
        svg("line", { x1: x(r.hi), x2: x(r.hi), y1: cy - 5, y2: cy + 5, stroke: r.color || "#333" }));
    }
    if (r.value != null && Number.isFinite(r.value)) {
      g.append(svg("circle", { cx: x(r.value), cy, r: 4.5, fill: r.color || "#333" }));
    }
    root.append(g);
  });
  return root;
}

// Points over time with vertical interval whiskers and a horizontal band: rows [{t (ms since epoch),
// value, lo, hi, flagged, href, label}], band {lo, hi, center} or null; yLabel with its unit.
export function timeBandChart({ id, rows, band, yLabel, width = 640, height = 240 }) {
  const m = { l: 62, r: 14, t: 12, b: 40 };
  const pw = width - m.l - m.r;
  const ph = height - m.t - m.b;
  const ts = rows.map((r) => r.t);
  const vals = rows.flatMap((r) => [r.lo, r.hi, r.value]).concat(band ? [band.lo, band.hi] : [])
    .filter((v) => v != null && Number.isFinite(v));
  let [t0, t1] = [Math.min(...ts), Math.max(...ts)];
  if (!(t1 > t0)) [t0, t1] = [t0 - 86400e3, t1 + 86400e3];
  let [lo, hi] = [Math.min(...vals), Math.max(...vals)];
  const pad = (hi - lo) * 0.08 || Math.abs(hi) * 0.1 || 1;
  lo -= pad;
  hi += pad;
  const tp = (t1 - t0) * 0.04;
  t0 -= tp;
  t1 += tp;
  const x = (t) => m.l + ((t - t0) / (t1 - t0)) * pw;
  const y = (v) => m.t + ph - ((v - lo) / (hi - lo)) * ph;
  const root = svg("svg", { id, class: "plot", width, height, viewBox: `0 0 ${width} ${height}`, role: "img" });
  if (band && Number.isFinite(band.lo) && Number.isFinite(band.hi)) {
    root.append(svg("rect", { x: m.l, width: pw, y: y(Math.min(band.hi, hi)), height: Math.max(0, y(Math.max(band.lo, lo)) - y(Math.min(band.hi, hi))),
      class: "band", dataset: { lo: band.lo, hi: band.hi } }, svg("title", {}, `fleet band ${tickLabel(band.lo)} to ${tickLabel(band.hi)}`)));
    if (band.center != null) root.append(svg("line", { x1: m.l, x2: m.l + pw, y1: y(band.center), y2: y(band.center), class: "ref" }));
  }
  for (const t of niceTicks(lo, hi)) {
    root.append(svg("line", { x1: m.l, x2: m.l + pw, y1: y(t), y2: y(t), class: "grid" }),
      svg("text", { x: m.l - 4, y: y(t) + 4, "text-anchor": "end", "font-size": FONT }, tickLabel(t)));
  }
  const days = [...new Set(rows.map((r) => new Date(r.t).toISOString().slice(0, 10)))];
  const step = Math.max(1, Math.ceil(days.length / 6));
  days.filter((_, i) => i % step === 0).forEach((d) => {
    const t = Date.parse(`${d}T00:00:00Z`);
    if (t >= t0 && t <= t1) root.append(svg("text", { x: x(t), y: m.t + ph + 14, "text-anchor": "middle", "font-size": FONT }, d));
  });
  root.append(svg("text", { x: 12, y: m.t + ph / 2, transform: `rotate(-90 12 ${m.t + ph / 2})`, "text-anchor": "middle",
    "font-size": FONT }, yLabel), svg("text", { x: m.l + pw / 2, y: m.t + ph + 32, "text-anchor": "middle", "font-size": FONT },
    "log start (UTC)"));
  for (const r of rows) {
    if (r.value == null || !Number.isFinite(r.value)) continue;
    const cx = x(r.t);
    const mark = svg("g", { class: r.flagged ? "point flagged" : "point", dataset: { value: r.value, t: r.t } },
      svg("title", {}, `${r.label}: ${tickLabel(r.value)} [${tickLabel(r.lo ?? NaN)}, ${tickLabel(r.hi ?? NaN)}]`));
    if (r.lo != null && r.hi != null) mark.append(svg("line", { x1: cx, x2: cx, y1: y(r.lo), y2: y(r.hi), class: "whisker" }));
    mark.append(svg("circle", { cx, cy: y(r.value), r: r.flagged ? 5.5 : 4 }));
    if (r.href) {
      const a = svg("a", { href: r.href });
      a.append(mark);
      root.append(a);
    } else root.append(mark);
  }
  root.append(svg("line", { x1: m.l, x2: m.l, y1: m.t, y2: m.t + ph, class: "axis" }),
    svg("line", { x1: m.l, x2: m.l + pw, y1: m.t + ph, y2: m.t + ph, class: "axis" }));
  return root;
}

// Per category a vertical band (lo-hi) with its median tick, a nominal marker (open circle) and a
// measured point, red when it falls outside the band: rows [{label, lo, mid, hi, nominal, measured, note}].
export function bandChart({ id, rows, yLabel, width = 900, height = 280 }) {
  const m = { l: 62, r: 14, t: 26, b: 40 };
  const pw = width - m.l - m.r;
  const ph = height - m.t - m.b;
  const vals = rows.flatMap((r) => [r.lo, r.hi, r.nominal, r.measured]).filter((v) => v != null && Number.isFinite(v));
  let lo = Math.min(...vals);
  let hi = Math.max(...vals);
  if (!vals.length) [lo, hi] = [0, 1];
  const pad = (hi - lo) * 0.08 || 1;
  lo -= pad;
  hi += pad;
  const y = (v) => m.t + ph - ((v - lo) / (hi - lo)) * ph;
  const slot = pw / Math.max(1, rows.length);
  const root = svg("svg", { id, class: "plot", width, height, viewBox: `0 0 ${width} ${height}`, role: "img" });
  for (const t of niceTicks(lo, hi)) {
    root.append(svg("line", { x1: m.l, x2: m.l + pw, y1: y(t), y2: y(t), class: "grid" }),
      svg("text", { x: m.l - 4, y: y(t) + 4, "text-anchor": "end", "font-size": FONT }, tickLabel(t)));
  }
  root.append(svg("text", { x: 12, y: m.t + ph / 2, transform: `rotate(-90 12 ${m.t + ph / 2})`, "text-anchor": "middle",
    "font-size": FONT }, yLabel));
  const every = Math.max(1, Math.ceil(rows.length / 40));
  rows.forEach((r, i) => {
    const cx = m.l + (i + 0.5) * slot;
    const inside = r.measured != null && r.lo != null && r.measured >= r.lo && r.measured <= r.hi;
    const g = svg("g", { class: inside ? "band-item" : "band-item outside", dataset: { label: r.label, lo: r.lo ?? "",
      hi: r.hi ?? "", measured: r.measured ?? "", inside } }, svg("title", {}, `${r.label}: band ${tickLabel(r.lo ?? NaN)} to ` +
      `${tickLabel(r.hi ?? NaN)}, median ${tickLabel(r.mid ?? NaN)}, nominal ${tickLabel(r.nominal ?? NaN)}, measured ` +
      `${tickLabel(r.measured ?? NaN)}${r.note ? ` · ${r.note}` : ""}`));
    const bw = Math.max(3, Math.min(16, slot * 0.6));
    if (r.lo != null && r.hi != null) {
      g.append(svg("rect", { x: cx - bw / 2, width: bw, y: y(r.hi), height: Math.max(1, y(r.lo) - y(r.hi)), class: "mc-band" }));
      if (r.mid != null) g.append(svg("line", { x1: cx - bw / 2, x2: cx + bw / 2, y1: y(r.mid), y2: y(r.mid), class: "mc-mid" }));
    }
    if (r.nominal != null) g.append(svg("circle", { cx, cy: y(r.nominal), r: 3.5, class: "mc-nominal" }));
    if (r.measured != null) g.append(svg("circle", { cx, cy: y(r.measured), r: 4, class: inside ? "mc-measured" : "mc-measured outside" }));
    if (i % every === 0) root.append(svg("text", { x: cx, y: m.t + ph + 14, "text-anchor": "middle", "font-size": FONT }, r.label));
    root.append(g);
  });
  root.append(svg("text", { x: m.l + pw / 2, y: m.t + ph + 32, "text-anchor": "middle", "font-size": FONT }, "event"),
    svg("line", { x1: m.l, x2: m.l, y1: m.t, y2: m.t + ph, class: "axis" }),
    svg("line", { x1: m.l, x2: m.l + pw, y1: m.t + ph, y2: m.t + ph, class: "axis" }));
  const key = svg("g", { class: "legend" });
  key.append(svg("rect", { x: m.l, y: 6, width: 10, height: 12, class: "mc-band" }), svg("text", { x: m.l + 14, y: 16, "font-size": FONT }, "predicted 5-95 % (median tick)"),
    svg("circle", { cx: m.l + 210, cy: 12, r: 3.5, class: "mc-nominal" }), svg("text", { x: m.l + 218, y: 16, "font-size": FONT }, "nominal vehicle"),
    svg("circle", { cx: m.l + 330, cy: 12, r: 4, class: "mc-measured" }), svg("text", { x: m.l + 338, y: 16, "font-size": FONT }, "measured"),
    svg("circle", { cx: m.l + 410, cy: 12, r: 4, class: "mc-measured outside" }), svg("text", { x: m.l + 418, y: 16, "font-size": FONT }, "measured, outside the band"));
  root.append(key);
  return root;
}
