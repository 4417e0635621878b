// Vehicles: the list, registering one (a preset or the user's driveline file, the user's DBC and a signal
// map uploaded, or proposed from a stored log with the evidence per channel and edited on the page), every
// version of one, and two versions compared field by field (which driveline parameter changed, by how much).
import { api, upload } from "./api.js";
import { errorBox, fmt, h, utc } from "./util.js";

// #/vehicles/<name>[/<a>/<b>]: that vehicle's versions, versions a and b compared (the identify page links here)
export async function render(main, name, first, second) {
  const list = h("div", { id: "vehicles" });
  const detail = h("div", { id: "vehicle-detail" });
  main.append(h("h1", {}, "Vehicles"), await registration(refresh),
    h("section", { class: "card" }, h("h2", {}, "Vehicles (latest version)"), list), detail);

  async function refresh() {
    const vs = await api("/vehicles");
    list.replaceChildren(vs.length ? h("table", { id: "vehicle-table" },
      h("thead", {}, h("tr", {}, ["name", "latest version", "created", "model", ""].map((c) => h("th", {}, c)))),
      h("tbody", {}, vs.map((v) => h("tr", {}, h("td", {}, h("strong", {}, v.name)), h("td", { class: "num" }, v.version),
        h("td", {}, utc(v.created_at)), h("td", {}, (v.summary.stages || []).join(", ") || v.summary.model || "-"),
        h("td", {}, h("button", { onclick: () => versions(v.name) }, "versions"))))))
      : h("p", { class: "muted" }, "No vehicles yet."));
  }

  async function versions(vname, pick = []) {
    try {
      const vs = await api(`/vehicles/${encodeURIComponent(vname)}/versions`);
      const a = h("select", { id: "compare-a" }, vs.map((v) => h("option", { value: v.version }, `v${v.version}`)));
      const b = h("select", { id: "compare-b" }, vs.map((v) => h("option", { value: v.version }, `v${v.version}`)));
      const known = (x) => vs.some((v) => String(v.version) === String(x));
      if (pick.length === 2 && pick.every(known)) {
        [a.value, b.value] = pick;
      } else if (vs.length > 1) {
        a.value = vs[vs.length - 2].version;
        b.value = vs[vs.length - 1].version;
      }
      const out = h("div", { id: "compare-result" });
      const compare = async () => {
        try {
          out.replaceChildren(diffTable(await api(`/vehicles/${encodeURIComponent(vname)}/compare?a=${a.value}&b=${b.value}`)));
        } catch (err) {
          out.replaceChildren(errorBox(err));
        }
      };
      detail.replaceChildren(h("section", { class: "card" }, h("h2", {}, `${vname}: ${vs.length} version(s)`),
        h("table", {}, h("thead", {}, h("tr", {}, ["version", "created", "sha256", "from diagnosis"].map((c) => h("th", {}, c)))),
          h("tbody", {}, vs.map((v) => h("tr", {}, h("td", { class: "num" }, v.version), h("td", {}, utc(v.created_at)),
            h("td", {}, h("code", {}, v.sha256.slice(0, 12))), h("td", {}, v.summary.diagnosis ? v.summary.diagnosis.id : "-"))))),
        h("div", { class: "toolbar" }, "compare ", a, " with ", b, h("button", { id: "compare", onclick: compare }, "Compare")), out));
      if (vs.length > 1) compare();
    } catch (err) {
      detail.replaceChildren(errorBox(err));
    }
  }

  function diffTable(doc) {
    const changed = doc.fields.filter((f) => f.changed);
    const figures = h("table", { id: "compare-figures" },
      h("thead", {}, h("tr", {}, ["figure", `v${doc.a}`, `v${doc.b}`, "ratio"].map((c) => h("th", {}, c)))),
      h("tbody", {}, doc.figures.map((f) => h("tr", { class: f.ratio != null && Math.abs(f.ratio - 1) > 1e-9 ? "changed" : null },
        h("td", {}, f.unit === "-" ? f.label : `${f.label} (${f.unit})`), h("td", { class: "num" }, show(f.a)),
        h("td", { class: "num" }, show(f.b)), h("td", { class: "num" }, f.ratio == null ? "" : `${fmt(f.ratio, 3)}x`)))));
    const identified = ["a", "b"].filter((side) => doc.provenance[side]).map((side) => {
      const p = doc.provenance[side];
      const fitted = Object.entries(p.fitted || {}).map(([k, v]) => `${k} ${fmt(v.ratio, 2)}x [${show(v.lo)}, ${show(v.hi)}] ${v.unit}`);
      return h("p", { class: "provenance" }, `v${doc[side]} identified from ${p.identified_from} on ${p.date}, ` +
        `${p.events} events of ${(p.logs || []).map((l) => l.name).join(", ")}: ${fitted.join("; ") || "nothing off the file"}`);
    });
    return h("div", {}, figures, ...identified, h("p", {}, `${changed.length} of ${doc.fields.length} driveline fields differ between v${doc.a} and v${doc.b}` +
      (doc.files_changed.length ? `; files changed: ${doc.files_changed.join(", ")}` : "; DBC and signal map identical")),
    h("label", {}, h("input", { type: "checkbox", onchange: (e) => {
      for (const tr of e.target.closest("div").querySelectorAll("tbody tr:not(.changed)")) tr.hidden = !e.target.checked;
    } }), " show unchanged fields"),
    h("table", { id: "compare-table" }, h("thead", {}, h("tr", {}, ["field", `v${doc.a}`, `v${doc.b}`, "change", "ratio"].map((c) => h("th", {}, c)))),
      h("tbody", {}, doc.fields.map((f) => h("tr", { class: f.changed ? "changed" : null, hidden: !f.changed },
        h("td", {}, h("code", {}, f.field)), h("td", { class: "num" }, show(f.a)), h("td", { class: "num" }, show(f.b)),
        h("td", { class: "num" }, f.delta == null ? "" : (f.delta > 0 ? "+" : "") + f.delta.toPrecision(4)),
        h("td", { class: "num" }, f.ratio == null ? "" : `${fmt(100 * (f.ratio - 1), 1)} %`))))));
  }
  await refresh();
  if (name) await versions(name, first && second ? [first, second] : []);
}

function show(v) {
  if (v === null || v === undefined) return "-";
  return typeof v === "number" ? String(+v.toPrecision(6)) : JSON.stringify(v);
}

const PRESETS = ["paper", "single_reduction", "chain_drive", "paper_fitted"];

// The registration form: every file goes up through the page (POST /vehicles, multipart).
async function registration(onStored) {
  const name = h("input", { id: "vehicle-name", placeholder: "name, e.g. my-ev", required: true, pattern: "[a-z0-9_\\-]+" });
  const preset = h("select", { id: "vehicle-preset" }, PRESETS.map((p) => h("option", { value: p }, p)));
  const driveline = h("input", { id: "vehicle-driveline", type: "file", accept: ".toml" });
  const dbc = h("input", { id: "vehicle-dbc", type: "file", accept: ".dbc,.kcd,.sym,.arxml,.xml" });
  const mapFile = h("input", { id: "vehicle-map-file", type: "file", accept: ".toml" });
  const log = h("select", { id: "vehicle-log" }, h("option", { value: "" }, "a stored log ..."));
  const changes = h("input", { id: "vehicle-map-changes", size: 44,
    placeholder: "changes: ROLE=Message.Signal; ROLE=-; invert ROLE" });
  const mapText = h("textarea", { id: "vehicle-map", rows: 10, cols: 70, spellcheck: "false",
    placeholder: "signal map TOML: proposed from a log, or leave empty for the uploaded map (else the project's)" });
  const evidence = h("div", { id: "vehicle-evidence" });
  const msg = h("span", { id: "vehicle-msg" });
  try {
    for (const l of await api("/logs?limit=1000")) log.append(h("option", { value: l.id }, `${l.filename} (${l.id})`));
  } catch (_) {
    /* no logs readable: the proposal is unavailable, the rest of the form works */
  }

  const propose = async () => {
    if (!log.value) {
      evidence.replaceChildren(h("p", { class: "muted" }, "Upload a log of the vehicle on the Logs page and choose it here."));
      return;
    }
    evidence.replaceChildren(h("p", { class: "muted" }, "reading the log ..."));
    const fields = { log_id: log.value, map: changes.value.split(";").map((x) => x.trim()).filter(Boolean).join("\n") };
    if (dbc.files[0]) fields.dbc = dbc.files[0];
    try {
      const p = await upload("/vehicles/signal-map-proposal", fields, () => {});
      mapText.value = p.signal_map_toml;
      evidence.replaceChildren(proposalTable(p));
    } catch (err) {
      evidence.replaceChildren(errorBox(err));
    }
  };

  const form = h("form", { id: "vehicle-form" },
    h("div", { class: "toolbar" }, h("label", {}, "name ", name), h("label", {}, "preset ", preset),
      h("label", {}, "or driveline TOML ", driveline)),
    h("div", { class: "toolbar" }, h("label", {}, "DBC ", dbc), h("label", {}, "signal map TOML ", mapFile)),
    h("div", { class: "toolbar" }, "propose the signal map from ", log, changes,
      h("button", { type: "button", id: "vehicle-propose", onclick: propose }, "Propose map")),
    evidence, mapText,
    h("div", { class: "toolbar" }, h("button", { class: "primary", type: "submit", id: "vehicle-register" }, "Register"), msg));
  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    const fields = { name: name.value };
    if (driveline.files[0]) fields.driveline = driveline.files[0];
    else fields.preset = preset.value;
    if (dbc.files[0]) fields.dbc = dbc.files[0];
    if (mapText.value.trim()) fields.signal_map = new File([mapText.value], "signals.map.toml", { type: "application/toml" });
    else if (mapFile.files[0]) fields.signal_map = mapFile.files[0];
    try {
      const v = await upload("/vehicles", fields, () => {});
      msg.textContent = v.unchanged ? `${v.name} v${v.version} unchanged` : `stored ${v.name} v${v.version}`;
      await onStored();
    } catch (err) {
      msg.replaceChildren(errorBox(err));
    }
  });
  return h("section", { class: "card" }, h("h2", {}, "Register a vehicle"),
    h("p", { class: "muted" }, "A preset or your driveline file, your DBC (default: the project's) and a signal map: upload one, " +
      "or propose it from a stored log with the evidence per channel, edit it below, then register."), form);
}

function proposalTable(p) {
  const rows = p.channels.map((c) => h("tr", {},
    h("td", {}, h("code", {}, c.channel)), h("td", {}, c.source + (c.chosen_by === "user" ? " (yours)" : "")),
    h("td", {}, (c.dbc_unit || "-") + (c.factor !== 1 ? ` x${+c.factor.toPrecision(4)}` : "")),
    h("td", { class: "num" }, fmt(c.rate_hz, 1)),
    h("td", { class: "num" }, `${fmt(c.minimum, 1)}..${fmt(c.maximum, 1)} ${c.unit}`),
    h("td", { class: "num" }, c.correlation === null ? "-" : c.correlation.toFixed(2)),
    h("td", {}, c.sign + (c.invert ? " (inverted)" : "") + (c.correlation_with ? `; ${c.correlation_with}` : ""))));
  return h("div", {}, h("p", {}, `${p.log_format}, ${p.frames} frames over ${fmt(p.duration_s, 1)} s; database ${p.database}` +
    (p.missing.length ? `; MISSING (every analysis needs them): ${p.missing.join(", ")}` : "")),
  h("table", { id: "proposal-table" }, h("thead", {}, h("tr", {},
    ["channel", "source (Message.Signal)", "unit", "rate (Hz)", "range (canonical unit)", "corr", "sign / correlation with"]
      .map((c) => h("th", {}, c)))), h("tbody", {}, rows)));
}
