// Logs: upload with a progress bar, the list (vehicle, duration, events, status of each analysis),
// start an analysis with a vehicle, delete.
import { api, upload } from "./api.js";
import { badge, bytes, duration, errorBox, h, progressBar, sleep, utc } from "./util.js";

export async function render(main) {
  const ctrl = new AbortController();
  const status = h("div", { id: "upload-status" });
  const file = h("input", { type: "file", id: "upload-file", name: "file" });
  const zone = h("input", { type: "text", id: "upload-tz", name: "tz", size: 16, placeholder: "e.g. Europe/Berlin",
    title: "time zone of the log's clock, for logs that do not record one: their start is then shown in UTC" });
  const described = h("input", { type: "file", id: "upload-format", name: "format_file", accept: ".toml",
    title: "only for a text log lashscope has no reader for: the TOML file describing its lines " +
      "(docs/ingest-readers.md, 'Describing a format'); kept with the log" });
  const send = h("button", { class: "primary", id: "upload-button", type: "submit" }, "Upload");
  const form = h("form", { class: "toolbar", id: "upload-form" }, file,
    h("label", {}, "log clock zone ", zone), h("label", {}, "format description (optional) ", described), send, status);
  const list = h("div", { id: "logs" });
  const formats = h("p", { class: "muted", id: "log-formats" }, "The same bytes are stored once.");
  api("/logs/formats", { signal: ctrl.signal }).then((fs) => {
    const labels = fs.map((f) => f.label);
    formats.textContent = `${labels.slice(0, -1).join(", ")} or ${labels.at(-1)}; gzip accepted. ` +
      "The same bytes are stored once.";
  }).catch(() => {});
  main.append(h("h1", {}, "Logs"),
    h("section", { class: "card" }, h("h2", {}, "Upload a CAN log"), formats, form),
    h("section", { class: "card" }, h("h2", {}, "Stored logs"), list));

  form.addEventListener("submit", async (e) => {
    e.preventDefault();
    if (!file.files.length) return;
    const f = file.files[0];
    send.disabled = true;
    status.replaceChildren(progressBar(0, `${f.name}: 0 %`));
    try {
      const fields = zone.value.trim() ? { tz: zone.value.trim(), file: f } : { file: f };
      if (described.files.length) fields.format_file = described.files[0];
      const rec = await upload("/logs", fields, (frac, done, total) => {
        status.replaceChildren(progressBar(frac, `${f.name}: ${bytes(done)} of ${bytes(total)}`));
      });
      status.replaceChildren(progressBar(1, `${f.name}: ${bytes(f.size)} sent`),
        h("span", {}, rec.duplicate ? `already stored as ${rec.id}` : `stored as ${rec.id}`,
          ` (${rec.frames} frames, ${duration(rec.duration_s)})`));
      await refresh();
    } catch (err) {
      status.replaceChildren(errorBox(err));
    } finally {
      send.disabled = false;
    }
  });

  let vehicles = [];
  async function refresh() {
    const [logs, analyses, vs] = await Promise.all([api("/logs?limit=1000"), api("/analyses?limit=1000"),
      api("/vehicles")]);
    vehicles = vs;
    const byLog = new Map();
    for (const a of analyses) byLog.set(a.log_id, [...(byLog.get(a.log_id) || []), a]);
    list.replaceChildren(logTable(logs, byLog, refresh));
    return analyses.some((a) => a.status === "queued" || a.status === "running");
  }

  function logTable(logs, byLog, again) {
    if (!logs.length) return h("p", { class: "muted", id: "no-logs" }, "No logs yet: upload one above.");
    const rows = logs.map((l) => {
      const runs = byLog.get(l.id) || [];
      const pick = h("select", { "aria-label": "vehicle", class: "vehicle-select" },
        vehicles.map((v) => h("option", { value: v.name }, `${v.name} v${v.version}`)));
      const start = h("button", { class: "analyse", disabled: !vehicles.length, onclick: async () => {
        try {
          const a = await api("/analyses", { method: "POST", json: { log_id: l.id, vehicle: pick.value } });
          location.hash = `#/analysis/${a.id}`;
        } catch (err) {
          list.prepend(errorBox(err));
        }
      } }, "Analyse");
      const del = h("button", { class: "danger", onclick: async () => {
        if (!confirm(`Delete ${l.filename} and its ${runs.length} analyses?`)) return;
        try {
          await api(`/logs/${l.id}`, { method: "DELETE" });
          again();
        } catch (err) {
          list.prepend(errorBox(err));
        }
      } }, "Delete");
      return h("tr", { dataset: { log: l.id } },
        h("td", {}, h("strong", {}, l.filename), h("div", { class: "muted" }, `${l.id} · ${l.format} · ${bytes(l.size_bytes)}`)),
        h("td", {}, l.start_time ? utc(l.start_time) : h("span", { class: "muted" }, "not in the log"),
          h("div", { class: "muted" }, `uploaded ${utc(l.created_at)}`)),
        h("td", { class: "num" }, duration(l.duration_s)),
        h("td", { class: "num" }, l.frames.toLocaleString("en")),
        h("td", {}, l.issues.length ? `${l.issues.length} read problem(s)` : "none"),
        h("td", {}, runs.length ? runs.map((a) => h("div", {},
          h("a", { href: `#/analysis/${a.id}` }, `${a.vehicle} v${a.vehicle_version}`), " ", badge(a.status),
          a.status === "done" ? ` ${a.summary.events ?? "?"} events`
            : a.status === "failed" ? h("div", { class: "failure", dataset: { code: a.job?.error?.code || "" } },
              `stopped at ${Math.round(100 * a.progress)} %: ${a.job?.error?.detail || "no reason recorded"} ` +
              `[${a.job?.error?.code || "unknown"}]`)
            : ` ${Math.round(100 * a.progress)} %`))
          : h("span", { class: "muted" }, "none")),
        h("td", {}, vehicles.length ? [pick, " ", start] : h("a", { href: "#/vehicles" }, "register a vehicle"),
          " ", del));
    });
    return h("div", { class: "scroll" }, h("table", { id: "log-table" },
      h("thead", {}, h("tr", {}, ["log", "start (UTC) / uploaded", "duration", "frames", "read problems",
        "analyses (vehicle, status, events)", ""].map((c) => h("th", {}, c)))), h("tbody", {}, rows)));
  }

  (async () => {
    try {
      while (!ctrl.signal.aborted) {
        const busy = await refresh();
        if (!busy) return;
        await sleep(2000);
      }
    } catch (err) {
      list.replaceChildren(errorBox(err));
    }
  })();
  return () => ctrl.abort();
}
