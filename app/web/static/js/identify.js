// Identify: a vehicle's base parameters learnt from its own logs. #/identify picks the vehicle, the logs
// to fit, the withheld logs and the parameters; #/identify/<id> shows progress, then what is off the file
// (in words, as a table and as ratios to the file with their intervals), the model-free first mode, the
// withheld drive's tracking before -> after, the identified vehicle file and "apply as a new version".
import { api, download } from "./api.js";
import { badge, errorBox, etaText, fmt, h, jobError, progressBar, ratioWords, sleep, svg, utc } from "./util.js";

const PARAMS = {
  stiffness: "torsional stiffness at the motor",
  damping: "first-mode damping ratio",
  mass: "vehicle mass",
  lash: "total lash at the motor",
};
const RECENT = "lashscope.identifications";

function recent() {
  try {
    return JSON.parse(localStorage.getItem(RECENT) || "[]");
  } catch (_) {
    return [];
  }
}

function remember(items) {
  localStorage.setItem(RECENT, JSON.stringify(items.slice(0, 20)));
}

export async function render(main, id) {
  return id ? result(main, id) : start(main);
}

// ---- #/identify: the form and the identifications started from this browser
async function start(main) {
  const [vehicles, logs] = await Promise.all([api("/vehicles"), api("/logs?limit=1000")]);
  const msg = h("div", { id: "identify-status" });
  main.append(h("h1", {}, "Identify a vehicle from its logs"),
    h("p", { class: "muted" }, "Fits the vehicle file's base parameters to tip-in and tip-out events of the logs ",
      "ticked \"fit\", with 90 % intervals, and checks the result on the logs ticked \"withheld\" (never fitted). ",
      "Identify before diagnosing: a data sheet that is off looks like a missing effect."));
  if (!vehicles.length || !logs.length) {
    main.append(h("p", { class: "note", id: "identify-missing" }, !vehicles.length
      ? h("span", {}, "No vehicle yet: ", h("a", { href: "#/vehicles" }, "register one"), ".")
      : h("span", {}, "No logs yet: ", h("a", { href: "#/logs" }, "upload the car's drives"), ".")), recentList());
    return null;
  }
  const vehicle = h("select", { id: "identify-vehicle", "aria-label": "vehicle" },
    vehicles.map((v) => h("option", { value: v.name }, `${v.name} v${v.version}`)));
  const roles = logs.map((l, i) => ({ log: l, choice: (role) => h("label", {}, h("input", { type: "radio",
    name: `role-${i}`, value: role, checked: role === "none" }), ` ${role === "none" ? "not used" : role}`) }));
  const table = h("table", { id: "identify-logs" },
    h("thead", {}, h("tr", {}, ["log", "duration", "uploaded", "use"].map((c) => h("th", { class: c === "duration" ? "num" : null }, c)))),
    h("tbody", {}, roles.map(({ log, choice }) => h("tr", { dataset: { log: log.id } },
      h("td", {}, h("strong", {}, log.filename), h("div", { class: "muted" }, log.id)),
      h("td", { class: "num" }, log.duration_s == null ? "-" : `${fmt(log.duration_s, 1)} s`),
      h("td", {}, utc(log.created_at)),
      h("td", { class: "roles" }, choice("fit"), choice("withheld"), choice("none"))))));
  const params = Object.entries(PARAMS).map(([name, label]) => h("label", { class: "param-choice" },
    h("input", { type: "checkbox", name: "param", value: name, checked: true }), ` ${label} (${name})`));
  const go = h("button", { class: "primary", id: "identify-start", type: "submit" }, "Identify");
  const form = h("form", { id: "identify-form" },
    h("div", { class: "toolbar" }, h("label", {}, "vehicle ", vehicle)),
    h("div", { class: "scroll" }, table),
    h("div", { class: "toolbar" }, h("span", { class: "muted" }, "parameters:"), params),
    h("div", { class: "toolbar" }, go, msg));
  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    const picked = (role) => [...table.querySelectorAll(`input[value="${role}"]:checked`)]
      .map((el) => el.closest("tr").dataset.log);
    const chosen = [...form.querySelectorAll("input[name=param]:checked")].map((el) => el.value);
    if (!picked("fit").length || !chosen.length) {
      msg.replaceChildren(errorBox(new Error("tick at least one log to fit and one parameter")));
      return;
    }
    go.disabled = true;
    try {
      const doc = await api("/identifications", { method: "POST", json: { vehicle: vehicle.value,
        log_ids: picked("fit"), validate_log_ids: picked("withheld"), params: chosen } });
      remember([{ id: doc.id, vehicle: `${doc.vehicle} v${doc.vehicle_version}`, at: new Date().toISOString() },
        ...recent().filter((r) => r.id !== doc.id)]);
      location.hash = `#/identify/${doc.id}`;
    } catch (err) {
      msg.replaceChildren(errorBox(err));
      go.disabled = false;
    }
  });
  main.append(h("section", { class: "card" }, h("h2", {}, "New identification"), form), recentList());
  return null;
}

function recentList() {
  const items = recent();
  return h("section", { class: "card", id: "identify-recent" }, h("h2", {}, "Started from this browser"),
    items.length ? h("ul", {}, items.map((r) => h("li", {}, h("a", { href: `#/identify/${r.id}` }, r.id),
      ` ${r.vehicle}, started ${utc(r.at)}`))) : h("p", { class: "muted" }, "none yet"));
}

// ---- #/identify/<id>: progress, then the result
async function result(main, id) {
  const ctrl = new AbortController();
  const head = h("div", { id: "identify-head" });
  main.append(h("h1", {}, "Identification ", h("code", {}, id)), head);
  let doc;
  try {
    for (;;) {
      doc = await api(`/identifications/${encodeURIComponent(id)}`, { signal: ctrl.signal });
      if (!head.isConnected) return null; // the user went to another page while this one polled
      if (!["queued", "running"].includes(doc.status) || ctrl.signal.aborted) break;
      head.replaceChildren(h("p", {}, badge(doc.status), ` ${doc.vehicle} v${doc.vehicle_version}: ${doc.stage}`),
        progressBar(doc.progress, `${doc.stage || doc.status}: ${Math.round(100 * doc.progress)} %${etaText(doc.job && doc.job.eta_s)}`));
      await sleep(1500);
    }
  } catch (err) {
    if (err.status !== 404) throw err;
    remember(recent().filter((r) => r.id !== id));
    head.replaceChildren(h("div", { class: "error", role: "alert", id: "identify-unknown" },
      `There is no identification ${id} on this server (it may have been deleted). `,
      h("a", { href: "#/identify" }, "Start one"), "."));
    main.dataset.state = "ready";
    return () => ctrl.abort();
  }
  if (doc.status !== "done" || !doc.result) {
    head.replaceChildren(h("p", {}, badge(doc.status), ` ${doc.vehicle} v${doc.vehicle_version}`),
      h("div", { id: "identify-error" }, jobError(doc.job.error, `the identification is ${doc.status}`)));
    main.dataset.state = "ready";
    return () => ctrl.abort();
  }
  const r = doc.result;
  const rows = Object.values(r.params);
  head.replaceChildren(
    h("p", {}, `${doc.vehicle} v${doc.vehicle_version}, fitted on `,
      r.logs.map((l) => `${l.name} (${l.events} events)`).join(", "), `: ${r.events} events`),
    h("section", { class: "card", id: "identify-headline" }, h("h2", {}, "What the logs say"),
      h("p", { class: "decision" }, headline(r)),
      r.not_identified.length ? h("p", { class: "muted" }, "Not identified (kept at the file's value): ",
        rows.filter((p) => !p.identified).map((p) => `${p.label}${p.note ? ` (${p.note})` : ""}`).join("; ")) : null),
    h("div", { class: "grid ident-grid" },
      h("section", { class: "card" }, h("h2", {}, "Ratio to the vehicle file (90 % interval)"), ratioChart(rows)),
      h("section", { class: "card", id: "identify-checks" }, h("h2", {}, "Checks"), checks(r))),
    h("section", { class: "card" }, h("h2", {}, "Parameters"), h("div", { class: "scroll" }, paramTable(rows))),
    actions(doc));
  main.dataset.state = "ready";
  return () => ctrl.abort();
}

const ratioOf = (p) => (p.ratio ?? (p.nominal ? p.value / p.nominal : null));
const ratioLo = (p) => (p.ratio_lo ?? (p.nominal && p.lo != null ? p.lo / p.nominal : null));
const ratioHi = (p) => (p.ratio_hi ?? (p.nominal && p.hi != null ? p.hi / p.nominal : null));

function headline(r) {
  const off = Object.values(r.params).filter((p) => p.named);
  const bound = Object.values(r.params).filter((p) => p.identified && p.at_bound);
  const words = off.length ? `The vehicle file is off: ${off.map((p) => ratioWords(p.label, ratioOf(p), ratioLo(p),
    ratioHi(p))).join("; ")}.` : "The logs agree with the vehicle file: no base parameter is off beyond its interval.";
  return [words, bound.length ? ` ${bound.map((p) => p.label).join(", ")} rest(s) on a prior bound: not trusted.` : ""];
}

function status(p) {
  if (!p.identified) return ["not-identified", "not identified"];
  if (p.at_bound) return ["at-bound", "at a prior bound"];
  if (p.named) return ["off-file", "off the file"];
  return ["matches", "matches the file"];
}

const num = (x, unit) => (x == null ? "-" : `${+x.toPrecision(4)}${unit && unit !== "-" ? ` ${unit}` : ""}`);

export function paramTable(rows, id = "identify-params") {
  return h("table", { id },
    h("thead", {}, h("tr", {}, ["parameter", "identified [90 % interval]", "file", "ratio to the file", "status"]
      .map((c, i) => h("th", { class: i && i < 4 ? "num" : null }, c)))),
    h("tbody", {}, rows.map((p) => {
      const [cls, words] = status(p);
      return h("tr", { dataset: { param: p.name, status: cls }, class: p.named ? "changed" : null },
        h("td", {}, p.label, " ", h("code", { class: "muted" }, p.name)),
        h("td", { class: "num" }, p.identified ? `${num(p.value, p.unit)} [${num(p.lo)}, ${num(p.hi)}]` : "-"),
        h("td", { class: "num" }, num(p.nominal, p.unit)),
        h("td", { class: "num ratio" }, p.identified ? `${fmt(ratioOf(p), 2)} [${fmt(ratioLo(p), 2)}, ${fmt(ratioHi(p), 2)}]` : "-"),
        h("td", {}, h("span", { class: `badge ${cls}` }, words), !p.identified && p.note ? h("div", { class: "muted" }, p.note) : null));
    })));
}

// One row per parameter: the interval as a bar, the value as a dot, a line at 1.0 (the file's value).
function ratioChart(rows) {
  const W = 680;
  const left = 290;
  const right = 20;
  const rowH = 30;
  const top = 10;
  const H = top + rows.length * rowH + 30;
  const ends = rows.filter((p) => p.identified).flatMap((p) => [ratioLo(p), ratioHi(p), ratioOf(p)]).filter((x) => x != null);
  const lo = Math.min(0.5, ...ends.map((x) => x - 0.05));
  const hi = Math.max(1.5, ...ends.map((x) => x + 0.05));
  const x = (v) => left + ((v - lo) / (hi - lo)) * (W - left - right);
  const ticks = [];
  for (let t = Math.ceil(lo * 4) / 4; t <= hi + 1e-9; t += 0.25) ticks.push(t);
  const plot = svg("svg", { id: "identify-chart", viewBox: `0 0 ${W} ${H}`, width: "100%", role: "img",
    "aria-label": "identified value as a ratio to the vehicle file, with its 90 % interval" },
  ticks.flatMap((t) => [svg("line", { x1: x(t), x2: x(t), y1: top, y2: H - 24, class: "grid-line" }),
    svg("text", { x: x(t), y: H - 8, "text-anchor": "middle", class: "tick" }, `${fmt(t, 2)}x`)]),
  svg("line", { x1: x(1), x2: x(1), y1: top - 4, y2: H - 24, class: "file-line" }),
  rows.map((p, i) => {
    const y = top + i * rowH + rowH / 2;
    const [cls] = status(p);
    return svg("g", { class: `row ${cls}`, dataset: { param: p.name } },
      svg("text", { x: left - 10, y: y + 4, "text-anchor": "end", class: "label" }, p.label),
      p.identified && ratioLo(p) != null
        ? [svg("rect", { x: x(ratioLo(p)), y: y - 6, width: Math.max(2, x(ratioHi(p)) - x(ratioLo(p))), height: 12, rx: 3,
          class: "interval" }, svg("title", {}, ratioWords(p.label, ratioOf(p), ratioLo(p), ratioHi(p)))),
        svg("circle", { cx: x(ratioOf(p)), cy: y, r: 4, class: "value" })]
        : svg("text", { x: x(1) + 8, y: y + 4, class: "tick" }, "not identified"));
  }));
  return h("div", {}, plot, h("p", { class: "muted" }, "Bar: 90 % interval; dot: identified value; ",
    "vertical line: the file's value (1.0x). Red: off the file; orange: at a prior bound."));
}

// the contact law the log chose (app/identify/form.py): its name, and each law's residual where both were fitted
function contactWords(c) {
  if (!c) return "the file's (no damped clearance to choose on)";
  const res = Object.entries(c.residual_to_noise || {}).map(([law, x]) => `${law} ${fmt(x, 2)}`).join(", ");
  const head = c.changed ? `${c.contact_damping} (the file says ${c.file})` : `${c.contact_damping}, as the file`;
  return res ? `${head}; residual / noise: ${res}` : head;
}

function checks(r) {
  const m = r.modal;
  const v = r.validation || {};
  const ci = (a) => (a ? `[${fmt(a[0], 2)}, ${fmt(a[1], 2)}]` : "");
  return h("dl", { class: "kv" },
    h("dt", {}, "first mode, model-free"),
    h("dd", { id: "identify-modal" }, m ? `${fmt(m.freq_hz, 2)} Hz ${ci(m.freq_ci)}, damping ratio ${fmt(m.zeta, 3)} `
      + `[${fmt(m.zeta_ci[0], 3)}, ${fmt(m.zeta_ci[1], 3)}] (${m.n_used} of ${m.n_windows} event windows)`
      : `not estimated${r.modal_error ? `: ${r.modal_error}` : ""}`),
    h("dt", {}, "rigid body, model-free"),
    h("dd", { id: "identify-rigid" }, r.rigid_body ? r.rigid_body.summary.replace(/^rigid body \(model-free\): /, "")
      .replace(/^rigid body \(model-free, /, "(")
      : "not estimated"),
    h("dt", {}, "contact damping"),
    h("dd", { id: "identify-contact" }, contactWords(r.contact_damping)),
    h("dt", {}, "residual / noise, fitted events"),
    h("dd", {}, `${fmt(r.residual_to_noise_before, 2)} with the file -> ${fmt(r.residual_to_noise_after, 2)} identified`),
    h("dt", {}, "withheld drive(s)"),
    h("dd", { id: "identify-validation" }, v.after && v.after.length
      ? [`median NRMSE ${fmt(v.nrmse_before, 3)} -> ${fmt(v.nrmse_after, 3)}; tracking `, badge(v.verdict_before),
        " -> ", badge(v.verdict_after),
        h("div", { class: "muted" }, v.after.map((a, i) => `${a.log}: ${fmt(v.before[i]?.nrmse, 3)} -> ${fmt(a.nrmse, 3)} `
          + `(${a.events} events)`).join("; "))]
      : h("span", { class: "muted" }, "none withheld: the result is not checked on a drive it was not fitted on")));
}

function actions(doc) {
  const out = h("div", { id: "identify-applied" },
    doc.applied ? h("span", {}, `applied as ${doc.applied.vehicle} v${doc.applied.version}; `,
      compareLink(doc.applied.vehicle, doc.vehicle_version, doc.applied.version)) : null);
  const file = `${doc.vehicle}-identified.toml`;
  const link = h("a", { href: doc.links.vehicle, download: file, id: "identify-download", onclick: async (e) => {
    e.preventDefault(); // through fetch, so that the API key goes with it
    try {
      await download(doc.links.vehicle, file, "application/toml");
    } catch (err) {
      out.replaceChildren(errorBox(err));
    }
  } }, "Download the identified vehicle file (TOML)");
  const apply = h("button", { class: "primary", id: "identify-apply", onclick: async () => {
    apply.disabled = true;
    try {
      const a = await api(`/identifications/${doc.id}/apply`, { method: "POST" });
      out.replaceChildren(h("span", {}, `stored ${a.vehicle} v${a.version} (from ${a.from}); `,
        compareLink(a.vehicle, doc.vehicle_version, a.version)));
    } catch (err) {
      out.replaceChildren(errorBox(err));
    } finally {
      apply.disabled = false;
    }
  } }, "Apply as new vehicle version");
  return h("section", { class: "card" }, h("h2", {}, "The identified vehicle"),
    h("div", { class: "toolbar" }, link, h("span", {}, " · "), apply, out));
}

// the vehicle's page with the version identified from and the one stored from it compared (figures and fields)
function compareLink(vehicle, from, to) {
  return h("a", { href: `#/vehicles/${encodeURIComponent(vehicle)}/${from}/${to}` }, `compare v${from} with v${to}`);
}
