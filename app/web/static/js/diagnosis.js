// Diagnosis view: progress, then the decision as a headline with its details below, the charts
// (held-out residual by event, phase and band before and after the chosen fit; measured, baseline
// and fitted speed of held-out events), the candidates compared on held-out shrink with intervals,
// the identifiability of the fitted parameters, where the gap lies, the remainder; apply the effect
// as a new vehicle version, validate it on a withheld drive. When the log says the vehicle file
// itself is off (base parameters identified first), a card lists them with their ratios to the file.
import { api } from "./api.js";
import { lineChart } from "./chart.js";
import { paramTable } from "./identify.js";
import { barChart, intervalChart } from "./plots.js";
import { badge, errorBox, etaText, fmt, h, jobError, progressBar, ratioWords, sleep } from "./util.js";

export const DIAG_COLORS = { measured: "#111111", baseline: "#1f77b4", fitted: "#d62728", validation: "#7b2fbe" };

const pct = (iv) => (iv && iv.value != null ? `${fmt(100 * iv.value, 0)} % [${fmt(100 * iv.lo, 0)}, ${fmt(100 * iv.hi, 0)}]` : "-");

// The decision in one line: what explains the gap and by how much (held-out), or why nothing does.
export function headline(d, titles) {
  const names = d.top.map((t) => titles[t] || t).join(" + ");
  switch (d.status) {
    case "explained": return `Explained by ${names}: removes ${pct(d.heldout_shrink)} of the held-out residual`;
    case "partial": return `Partly explained by ${names}: removes ${pct(d.heldout_shrink)} of the held-out residual; some is left`;
    case "ambiguous": return `Ambiguous: ${(d.confusable || d.top).map((t) => titles[t] || t).join(" or ")} fit equally well`;
    case "none_of_candidates": return "None of the candidate effects explains the gap";
    case "no_significant_gap": return "No significant gap: the simulation matches the log within noise";
    case "insufficient_data": return "Not enough events to decide";
    case "base_parameters": return `The vehicle file is off: ${(d.base_parameters || []).map((p) => p.label).join(", ") || "its base parameters"}`;
    default: return d.status;
  }
}

const interval = (iv, k = 100, unit = " %") => (iv && iv.value != null
  ? `${fmt(iv.value * k, 1)}${unit} [${fmt(iv.lo * k, 1)}, ${fmt(iv.hi * k, 1)}]` : "-");

export async function render(main, id) {
  const ctrl = new AbortController();
  const head = h("div", {});
  const analysisId = id.split("--dg")[0];
  main.append(h("h1", {}, "Diagnosis ", h("code", {}, id)),
    h("p", {}, "of analysis ", h("a", { href: `#/analysis/${analysisId}` }, analysisId)), head);
  let doc;
  for (;;) {
    doc = await api(`/diagnoses/${id}`, { signal: ctrl.signal });
    if (!["queued", "running"].includes(doc.status) || ctrl.signal.aborted) break;
    head.replaceChildren(h("p", {}, badge(doc.status), ` ${doc.stage}`),
      progressBar(doc.progress, `${doc.stage}: ${Math.round(100 * doc.progress)} %${etaText(doc.eta_s)}`));
    await sleep(1500);
  }
  if (doc.status !== "done") {
    head.replaceChildren(badge(doc.status), jobError(doc.error, `diagnosis is ${doc.status}`));
    return () => ctrl.abort();
  }
  const r = doc.report;
  const d = r.decision;
  const titles = Object.fromEntries([...r.candidates, ...r.pairs].map((c) => [c.id, c.title]));
  const chartsCard = h("section", { class: "card", id: "diagnosis-charts" }, h("h2", {}, "Held-out residual before and after the fit"),
    h("p", { class: "muted" }, "loading the charts ..."));
  head.replaceChildren(...[
    r.read && r.read.damaged ? h("div", { class: "note", id: "read-report" },
      h("strong", {}, r.read.truncated ? "truncated log" : "damaged log"), `: ${r.read.note}`) : "",
    h("section", { class: "card", id: "decision" },
      h("p", { class: "headline", id: "headline" }, badge(d.status), " ", headline(d, titles)),
      h("p", { class: "decision" }, d.reason),
      h("dl", { class: "kv" },
        h("dt", {}, "effect(s)"), h("dd", {}, d.top.length ? d.top.join(" + ") : "none"),
        h("dt", {}, "residual / noise before"), h("dd", {}, interval(d.residual_to_noise_before, 1, "")),
        h("dt", {}, "residual / noise after"), h("dd", {}, fmt(d.residual_to_noise_after, 2)),
        h("dt", {}, "explained share (held out)"), h("dd", {}, interval(d.explained_share)),
        h("dt", {}, "held-out shrink"), h("dd", {}, interval(d.heldout_shrink)),
        h("dt", {}, "split"), h("dd", {}, `${r.split.calibration.length} calibration, ${r.split.heldout.length} held-out events (seed ${r.split.seed})`),
        h("dt", {}, "noise floor"), h("dd", {}, `${fmt(r.noise_floor.sigma_rpm, 2)} rpm`))),
    baseParameters(d, titles), chartsCard, candidates(r), identifiability(r), identification(r.identification, d.reason),
    remainder(d), actions(id, d, doc, ctrl, r), where(r)].filter(Boolean));
  await charts(chartsCard, id, r, ctrl.signal);
  // the first frame with the decision and the charts: ms since navigation start (bench/dashboard.py)
  await new Promise(requestAnimationFrame);
  main.dataset.paintedMs = performance.now().toFixed(0);
  main.dataset.state = "ready";
  return () => ctrl.abort();
}

// The vehicle file's base parameters the log says are off (ratios to the file's values, 90 % intervals), and the
// effects that would change the log alike on a right data sheet, to first order (mimicked_by).
function baseParameters(d, titles) {
  const items = d.base_parameters || [];
  if (!items.length && !d.identify_first) return null;
  const unit = (x, u) => `${+x.toPrecision(4)}${u && u !== "-" ? ` ${u}` : ""}`;
  return h("section", { class: "card", id: "base-parameters" }, h("h2", {}, "Vehicle file off"),
    d.identify_first ? h("p", { class: "note", id: "identify-first" }, "Identify the vehicle first: a base parameter ",
      "rests on the bound of what this log can say, so no effect is attributed until the vehicle file is corrected. ",
      h("a", { href: "#/identify" }, "Identify it from its logs"), ".") : null,
    h("ul", {}, items.map((p) => h("li", { dataset: { param: p.name } }, ratioWords(p.label, p.ratio, p.lo, p.hi),
      h("span", { class: "muted" }, ` (${unit(p.value, p.unit)}; file ${unit(p.nominal, p.unit)})`)))),
    (d.mimicked_by || []).length ? h("p", { class: "note", id: "mimicked-by" }, "On a right data sheet ",
      d.mimicked_by.map((m) => `${titles[m.effect] || m.effect.replaceAll("_", " ")} `
        + `(${Math.round(100 * m.linear_share)} %)`).join(", "), " would change the log alike: the share of the file's residual above the noise it would remove, ",
      "to first order. Where the data sheet is known to be right, rule that out before correcting the file.") : null,
    items.length && !d.identify_first ? h("p", { class: "muted" }, "Applying this diagnosis stores these values as a ",
      "new vehicle version; the Identify page fits them on several logs, with a withheld drive.") : null);
}

// What the identification run inside the diagnosis found (on the calibration events), compactly; its note
// when the decision's reason does not already say it.
function identification(ident, reason) {
  if (!ident) return null;
  const card = h("section", { class: "card", id: "diagnosis-identification" }, h("h2", {}, "Base parameters identified first"));
  if (ident.skipped) card.append(h("p", { class: "muted" }, `skipped: ${ident.skipped}`));
  else {
    if (ident.note && ident.note !== reason) card.append(h("p", {}, ident.note));
    card.append(h("div", { class: "scroll" }, paramTable(Object.values(ident.params || {}), "diagnosis-identification-params")));
  }
  return card;
}

function remainder(d) {
  const rem = d.remainder || {};
  const words = rem.status === "noise" ? "What is left after the chosen fit is at the noise floor."
    : rem.status === "structured" ? `What is left is above noise in: ${(rem.where || []).join(", ") || "-"}` +
      (rem.explained_by_candidates === false ? "; none of the candidates explains it." : ".") : "No remainder computed.";
  const rtn = d.remainder_to_noise || {};
  return h("section", { class: "card", id: "remainder" }, h("h2", {}, "Remainder"), h("p", {}, words),
    h("dl", { class: "kv" },
      h("dt", {}, "ratio to noise"), h("dd", {}, fmt(rem.ratio_to_noise, 2)),
      h("dt", {}, "overall"), h("dd", {}, interval(rtn.overall, 1, "")),
      h("dt", {}, "impact"), h("dd", {}, interval(rtn.impact, 1, "")),
      ...Object.entries(rtn.phases || {}).flatMap(([p, iv]) => [h("dt", {}, `phase ${p}`), h("dd", {}, interval(iv, 1, ""))])));
}

function params(fit) {
  return Object.entries(fit.params || {}).map(([effect, ps]) => h("div", {}, `${effect}: `,
    Object.entries(ps).map(([k, v]) => `${k} = ${typeof v === "number" ? v.toPrecision(4) : v}`).join(", ")));
}

// The charts from /diagnoses/{id}/charts; a diagnosis without them says why in the card.
async function charts(card, id, r, signal) {
  let c;
  try {
    c = await api(`/diagnoses/${id}/charts`, { signal });
  } catch (err) {
    card.replaceChildren(h("h2", {}, "Held-out residual before and after the fit"), errorBox(err));
    return;
  }
  const after = c.fitted ? `after: + ${c.fitted}` : "after";
  const groups = (rows) => [{ label: "before (baseline)", color: DIAG_COLORS.baseline, values: rows.map((x) => x.before) },
    ...(c.fitted ? [{ label: after, color: DIAG_COLORS.fitted, values: rows.map((x) => x.after) }] : [])];
  const noise = { value: 1, label: "noise floor" };
  const overlays = h("div", { class: "grid", id: "diagnosis-overlays" });
  card.replaceChildren(h("h2", {}, `Held-out residual before and after the fit (${c.heldout} events)`),
    h("p", { class: "muted" }, "Residual / noise: the residual's energy over what the noise floor ",
      `(${fmt(c.noise_sigma_rpm, 2)} rpm) alone would leave; 1 is noise. Log scale.`),
    h("div", { class: "grid" },
      h("div", {}, h("h3", {}, "by event"), barChart({ id: "residual-by-event", categories: c.events.map((e) => `#${e.index}`),
        groups: groups(c.events), yLabel: "residual / noise (-)", log: true, ref: noise, width: Math.max(420, 26 * c.events.length + 90) })),
      h("div", {}, h("h3", {}, "by phase"), barChart({ id: "residual-by-phase", categories: c.phases.map((p) => p.phase),
        groups: groups(c.phases), yLabel: "residual / noise (-)", log: true, ref: noise, width: 460 })),
      h("div", {}, h("h3", {}, "by frequency band"), barChart({ id: "residual-by-band", categories: c.bands.map((b) => b.band),
        groups: groups(c.bands), yLabel: "share of baseline residual (-)", width: 360 }))),
    h("h3", {}, "Held-out events: measured, baseline and fitted motor speed"),
    h("p", { class: "muted" }, h("span", { style: `color:${DIAG_COLORS.measured}` }, "● measured"), " · ",
      h("span", { style: `color:${DIAG_COLORS.baseline}` }, "— baseline (calibrated vehicle)"), " · ",
      h("span", { style: `color:${DIAG_COLORS.fitted}` }, `— ${c.fitted ? `+ ${c.fitted}` : "no fit"}`),
      " · shaded: the predicted gap-open span. Time from the torque zero crossing."),
    overlays);
  await new Promise(requestAnimationFrame);
  const cols = Math.max(1, Math.floor((overlays.clientWidth + 12) / 452));
  const width = Math.max(400, Math.floor((overlays.clientWidth - 12 * (cols - 1)) / cols) - 14);
  for (const o of c.overlays) {
    const box = h("div", { class: "chart" });
    overlays.append(h("div", { class: "panel", dataset: { event: o.index } },
      h("h3", {}, `#${o.index} ${o.kind.replace("_", "-")}, held out`), box));
    const data = [o.t_s, o.measured_rpm, o.baseline_rpm, ...(o.fitted_rpm ? [o.fitted_rpm] : [])];
    const series = [{ label: "measured rpm", color: DIAG_COLORS.measured, points: true },
      { label: "baseline rpm", color: DIAG_COLORS.baseline, width: 1.5 },
      ...(o.fitted_rpm ? [{ label: `+ ${c.fitted} rpm`, color: DIAG_COLORS.fitted, width: 1.5 }] : [])];
    lineChart(box, data, { width, height: 220, series, xLabel: "time from torque zero crossing (s)", yLabel: "motor speed (rpm)",
      spans: [{ t0: o.gap_open_s, t1: o.gap_close_s, color: "rgba(123,47,190,0.12)" }],
      markers: () => [{ t: 0, color: "#666", label: "0", dash: true }] });
  }
  overlays.dataset.panels = c.overlays.length;
  if (!c.overlays.length) overlays.append(h("p", { class: "muted" }, "no held-out event to show"));
}

// The candidates' held-out shrink with 90 % intervals, best first; the chosen one in bold.
function shrinkChart(r) {
  const chosen = r.decision.top.join("+");
  const rows = [...r.candidates, ...r.pairs].filter((c) => c.heldout?.shrink)
    .sort((a, b) => (b.heldout.shrink.value ?? -1) - (a.heldout.shrink.value ?? -1))
    .map((c) => ({ label: c.title, value: 100 * c.heldout.shrink.value, lo: 100 * c.heldout.shrink.lo,
      hi: 100 * c.heldout.shrink.hi, strong: c.id === chosen, color: c.id === chosen ? DIAG_COLORS.fitted : "#555",
      note: c.heldout.significant ? "significant" : "not significant" }));
  if (!rows.length) return h("p", { class: "muted" }, "no candidate was scored");
  return intervalChart({ id: "shrink-chart", rows, xLabel: "held-out shrink of the residual energy (%), 90 % interval" });
}

// Which fitted parameters the data pin down: at a bound, trading off with another (correlation), or free.
function identifiability(r) {
  const chosen = [...r.candidates, ...r.pairs].find((c) => c.id === r.decision.top.join("+"))
    || [...r.candidates].sort((a, b) => (b.heldout?.shrink?.value ?? -1) - (a.heldout?.shrink?.value ?? -1))[0];
  if (!chosen) return null;
  const fit = chosen.fit || {};
  const atBound = new Set(fit.at_bound || []);
  const trades = fit.trade_offs || [];
  const rows = [];
  for (const [effect, ps] of Object.entries(fit.params || {})) {
    for (const [name, value] of Object.entries(ps)) {
      const key = `${effect}.${name}`;
      const with_ = trades.filter((t) => t.params.some((p) => p === key || p === name || p.endsWith(`.${name}`)));
      const bound = atBound.has(key) || atBound.has(name);
      const status = bound ? "at a bound" : with_.length ? "trades off" : "identified";
      rows.push(h("tr", { dataset: { param: key, status } }, h("td", {}, effect), h("td", {}, name),
        h("td", { class: "num" }, typeof value === "number" ? value.toPrecision(4) : String(value)),
        h("td", {}, badge(status === "identified" ? "good" : "partial"), ` ${status}`),
        h("td", {}, with_.map((t) => `${t.params.join(" ~ ")} (r = ${fmt(t.correlation, 2)})`).join("; ") || "-")));
    }
  }
  const pairs = r.decision.identifiability || [];
  return h("section", { class: "card", id: "identifiability" }, h("h2", {}, `Identifiability of the fitted parameters (${chosen.title})`),
    rows.length ? h("table", { id: "identifiability-table" }, h("thead", {}, h("tr", {},
      ["effect", "parameter", "fitted value (SI)", "identifiable", "trades off with"].map((c) => h("th", {}, c)))), h("tbody", {}, rows))
      : h("p", { class: "muted" }, "this fit has no parameters"),
    pairs.length ? h("ul", {}, pairs.map((p) => h("li", {}, `${p.params.join(" and ")} trade off (correlation ${fmt(p.correlation, 2)})`,
      p.identified ? `; ${p.identified.name} is taken from the identification: ${+Number(p.identified.value).toPrecision(4)} ${p.identified.unit || ""}` : ""))) : null);
}

function candidates(r) {
  const rows = [...r.candidates, ...r.pairs].map((c) => h("tr", { class: r.decision.top.join("+") === c.id ? "changed" : null },
    h("td", {}, h("strong", {}, c.title), h("div", { class: "muted" }, c.id)),
    h("td", { class: "num" }, interval(c.heldout.shrink)),
    h("td", { class: "num" }, interval(c.heldout.explained_share)),
    h("td", { class: "num" }, `${fmt(100 * c.heldout.improved_fraction, 0)} %`),
    h("td", {}, c.heldout.significant ? "yes" : "no"),
    h("td", { class: "num" }, fmt(c.heldout.residual_to_noise, 2)),
    h("td", {}, params(c.fit))));
  const na = Object.entries(r.candidates_not_applicable || {});
  return h("section", { class: "card", id: "candidates-card" }, h("h2", {}, "Candidates, scored on held-out events"),
    shrinkChart(r),
    h("div", { class: "scroll" }, h("table", { id: "candidates" }, h("thead", {}, h("tr", {},
      ["effect", "held-out shrink (90 % interval)", "explained share", "events improved", "significant",
        "residual / noise", "fitted parameters"].map((c) => h("th", {}, c)))), h("tbody", {}, rows))),
    na.length ? h("p", { class: "muted" }, "Not applicable: ", na.map(([k, v]) => `${k} (${v})`).join("; ")) : null);
}

function where(r) {
  const loc = r.localisation;
  if (!loc) return h("section", { class: "card" }, h("h2", {}, "Where the gap lies"), h("p", { class: "muted" }, "no baseline fit"));
  const top = loc.events.filter((e) => e.role === "heldout").sort((a, b) => (b.energy_share ?? 0) - (a.energy_share ?? 0)).slice(0, 8);
  return h("section", { class: "card", id: "where" }, h("h2", {}, "Where the gap lies (held-out events)"),
    h("div", { class: "grid" },
      h("table", {}, h("thead", {}, h("tr", {}, ["event", "kind", "t (s)", "share of residual", "RMS (rpm)"].map((c) => h("th", {}, c)))),
        h("tbody", {}, top.map((e) => h("tr", {}, h("td", {}, e.index), h("td", {}, e.kind), h("td", { class: "num" }, fmt(e.t_event_s, 2)),
          h("td", { class: "num" }, `${fmt(100 * e.energy_share, 1)} %`), h("td", { class: "num" }, fmt(e.rms_rpm, 1)))))),
      h("table", {}, h("thead", {}, h("tr", {}, ["phase", "share", "residual / noise"].map((c) => h("th", {}, c)))),
        h("tbody", {}, loc.phases.map((p) => h("tr", {}, h("td", {}, p.phase), h("td", { class: "num" }, `${fmt(100 * p.energy_share, 1)} %`),
          h("td", { class: "num" }, fmt(p.residual_to_noise, 2)))))),
      h("table", {}, h("thead", {}, h("tr", {}, ["band", "share", "coherence with torque"].map((c) => h("th", {}, c)))),
        h("tbody", {}, loc.bands.map((b) => h("tr", {}, h("td", {}, b.band), h("td", { class: "num" }, `${fmt(100 * b.energy_share, 1)} %`),
          h("td", { class: "num" }, fmt(b.coherence, 2))))))),
    loc.notes.length ? h("p", { class: "note" }, loc.notes.join(" ")) : null);
}

// A validation in words and beside the diagnosed log's own held-out shrink: how much of this other
// drive's gap the frozen effect removes.
function validationText(v, r) {
  const rows = [{ label: "held out, diagnosed log", value: 100 * r.decision.heldout_shrink?.value, lo: 100 * r.decision.heldout_shrink?.lo,
    hi: 100 * r.decision.heldout_shrink?.hi, color: DIAG_COLORS.fitted },
  { label: `withheld drive ${v.log_id}`, value: 100 * v.shrink?.value, lo: 100 * v.shrink?.lo, hi: 100 * v.shrink?.hi,
    color: DIAG_COLORS.validation, strong: true }];
  return h("div", { id: "validation" }, intervalChart({ id: "validation-chart", rows, xLabel: "shrink of the residual energy (%), 90 % interval" }), h("p", {}, `On ${v.log_id} (${v.events} events) the effect with its fitted values `,
    `shrinks the residual by ${interval(v.shrink)} and explains ${interval(v.explained_share)} of it above noise; `,
    `${fmt(100 * v.improved_fraction, 0)} % of the events improve; residual / noise ${fmt(v.residual_to_noise_baseline, 2)} `,
    `-> ${fmt(v.residual_to_noise_augmented, 2)}.`));
}

function actions(id, d, doc, ctrl, r) {
  const out = h("div", { id: "actions-result" });
  const card = h("section", { class: "card", id: "apply-validate" }, h("h2", {}, "Apply, and validate on a withheld drive"));
  if (!["explained", "partial", "ambiguous"].includes(d.status) && !(d.status === "base_parameters" && !d.identify_first)) {
    card.append(h("p", { class: "muted" }, `The decision is ${d.status}: there is no effect to apply.`));
    return card;
  }
  const applied = doc.applied ? `applied as ${doc.applied.vehicle} v${doc.applied.version}` : null;
  const apply = h("button", { class: "primary", id: "apply", onclick: async () => {
    try {
      const a = await api(`/diagnoses/${id}/apply`, { method: "POST", json: {} });
      out.replaceChildren(h("p", {}, `stored ${a.vehicle} v${a.version} (from ${a.from}); `,
        h("a", { href: "#/vehicles" }, "compare the versions")));
    } catch (err) {
      out.replaceChildren(errorBox(err));
    }
  } }, "Apply as a new vehicle version");
  const logs = h("select", { "aria-label": "log to validate on", id: "validate-log" });
  api("/logs?limit=1000").then((ls) => ls.forEach((l) => logs.append(h("option", { value: l.id }, `${l.filename} (${l.id})`))));
  const validate = h("button", { id: "validate", onclick: async () => {
    try {
      await api(`/diagnoses/${id}/validate`, { method: "POST", json: { log_id: logs.value } });
      for (;;) {
        const v = (await api(`/diagnoses/${id}`, { signal: ctrl.signal })).validation || {};
        out.replaceChildren(h("p", {}, "validation: ", badge(v.status || "queued")));
        if (v.status === "done") {
          out.append(validationText(v, r));
          return;
        }
        if (v.status === "failed") {
          out.append(jobError(v.error, "validation failed"));
          return;
        }
        await sleep(2000);
      }
    } catch (err) {
      out.replaceChildren(errorBox(err));
    }
  } }, "Validate on this log");
  card.append(h("div", { class: "toolbar" }, apply, applied ? h("span", { class: "muted" }, applied) : null,
    h("span", {}, " · "), logs, validate), out);
  if (doc.validation?.status === "done") out.append(validationText(doc.validation, r));
  return card;
}
