// Diagnosis view: progress, then the decision in words, where the gap lies (events, phases,
// bands), the candidates with their held-out scores and fitted parameters, the remainder;
// apply the effect as a new vehicle version, validate it on another log. When the log says the vehicle
// file itself is off (base parameters identified first), a card lists them with their ratios to the file.
import { api } from "./api.js";
import { paramTable } from "./identify.js";
import { badge, errorBox, fmt, h, jobError, progressBar, ratioWords, sleep } from "./util.js";

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
      progressBar(doc.progress, `${doc.stage}: ${Math.round(100 * doc.progress)} %`));
    await sleep(1500);
  }
  if (doc.status !== "done") {
    head.replaceChildren(badge(doc.status), jobError(doc.error, `diagnosis is ${doc.status}`));
    return () => ctrl.abort();
  }
  const r = doc.report;
  const d = r.decision;
  head.replaceChildren(
    r.read && r.read.damaged ? h("div", { class: "note", id: "read-report" },
      h("strong", {}, r.read.truncated ? "truncated log" : "damaged log"), `: ${r.read.note}`) : "",
    h("section", { class: "card", id: "decision" }, h("h2", {}, "Decision"),
      h("p", { class: "decision" }, badge(d.status), " ", d.reason),
      h("dl", { class: "kv" },
        h("dt", {}, "effect(s)"), h("dd", {}, d.top.length ? d.top.join(" + ") : "none"),
        h("dt", {}, "residual / noise before"), h("dd", {}, interval(d.residual_to_noise_before, 1, "")),
        h("dt", {}, "residual / noise after"), h("dd", {}, fmt(d.residual_to_noise_after, 2)),
        h("dt", {}, "explained share (held out)"), h("dd", {}, interval(d.explained_share)),
        h("dt", {}, "held-out shrink"), h("dd", {}, interval(d.heldout_shrink)),
        h("dt", {}, "split"), h("dd", {}, `${r.split.calibration.length} calibration, ${r.split.heldout.length} held-out events (seed ${r.split.seed})`),
        h("dt", {}, "noise floor"), h("dd", {}, `${fmt(r.noise_floor.sigma_rpm, 2)} rpm`))),
    baseParameters(d), identification(r.identification, d.reason), remainder(d), actions(id, d, doc, ctrl), candidates(r),
    where(r));
  main.dataset.state = "ready";
  return () => ctrl.abort();
}

// The vehicle file's base parameters the log says are off (ratios to the file's values, 90 % intervals).
function baseParameters(d) {
  const items = d.base_parameters || [];
  if (!items.length && !d.identify_first) return null;
  const unit = (x, u) => `${+x.toPrecision(4)}${u && u !== "-" ? ` ${u}` : ""}`;
  return h("section", { class: "card", id: "base-parameters" }, h("h2", {}, "Vehicle file off"),
    d.identify_first ? h("p", { class: "note", id: "identify-first" }, "Identify the vehicle first: a base parameter ",
      "rests on the bound of what this log can say, so no effect is attributed until the vehicle file is corrected. ",
      h("a", { href: "#/identify" }, "Identify it from its logs"), ".") : null,
    h("ul", {}, items.map((p) => h("li", { dataset: { param: p.name } }, ratioWords(p.label, p.ratio, p.lo, p.hi),
      h("span", { class: "muted" }, ` (${unit(p.value, p.unit)}; file ${unit(p.nominal, p.unit)})`)))),
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
  return h("section", { class: "card" }, h("h2", {}, "Candidates, scored on held-out events"),
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

// A validation in words: how much of this other drive's gap the frozen effect removes.
function validationText(v) {
  return h("div", { id: "validation" }, h("p", {}, `On ${v.log_id} (${v.events} events) the effect with its fitted values `,
    `shrinks the residual by ${interval(v.shrink)} and explains ${interval(v.explained_share)} of it above noise; `,
    `${fmt(100 * v.improved_fraction, 0)} % of the events improve; residual / noise ${fmt(v.residual_to_noise_baseline, 2)} `,
    `-> ${fmt(v.residual_to_noise_augmented, 2)}.`));
}

function actions(id, d, doc, ctrl) {
  const out = h("div", { id: "actions-result" });
  const card = h("section", { class: "card" }, h("h2", {}, "Apply and validate"));
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
          out.append(validationText(v));
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
  if (doc.validation?.status === "done") out.append(validationText(doc.validation));
  return card;
}
