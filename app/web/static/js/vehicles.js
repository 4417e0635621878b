// Vehicles: the list, a new vehicle from a preset, every version of one, and two versions compared
// field by field (which driveline parameter changed, by how much).
import { api, upload } from "./api.js";
import { errorBox, fmt, h, utc } from "./util.js";

export async function render(main) {
  const list = h("div", { id: "vehicles" });
  const detail = h("div", { id: "vehicle-detail" });
  const name = h("input", { id: "vehicle-name", placeholder: "name, e.g. my-ev", required: true, pattern: "[a-z0-9_-]+" });
  const preset = h("select", { id: "vehicle-preset" }, ["paper", "single_reduction", "chain_drive"].map((p) => h("option", { value: p }, p)));
  const msg = h("span", {});
  const form = h("form", { class: "toolbar", id: "vehicle-form" }, name, preset,
    h("button", { class: "primary", type: "submit" }, "Register"), msg);
  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    try {
      const v = await upload("/vehicles", { name: name.value, preset: preset.value }, () => {});
      msg.textContent = v.unchanged ? `${v.name} v${v.version} unchanged` : `stored ${v.name} v${v.version}`;
      await refresh();
    } catch (err) {
      msg.replaceChildren(errorBox(err));
    }
  });
  main.append(h("h1", {}, "Vehicles"),
    h("section", { class: "card" }, h("h2", {}, "Register a vehicle from a preset"),
      h("p", { class: "muted" }, "Uses the project's DBC and signal map. Own driveline TOML, DBC and map: POST /vehicles (API docs)."), form),
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

  async function versions(vname) {
    try {
      const vs = await api(`/vehicles/${encodeURIComponent(vname)}/versions`);
      const a = h("select", { id: "compare-a" }, vs.map((v) => h("option", { value: v.version }, `v${v.version}`)));
      const b = h("select", { id: "compare-b" }, vs.map((v) => h("option", { value: v.version }, `v${v.version}`)));
      if (vs.length > 1) {
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
    return h("div", {}, h("p", {}, `${changed.length} of ${doc.fields.length} driveline fields differ between v${doc.a} and v${doc.b}` +
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
}

function show(v) {
  if (v === null || v === undefined) return "-";
  return typeof v === "number" ? String(+v.toPrecision(6)) : JSON.stringify(v);
}
