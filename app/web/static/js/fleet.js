// Fleet page (#/fleet): per vehicle the lash estimate and the ripple over time, one point per log with
// its interval, against the fleet band; outliers flagged by the fleet report's own rule (GET /fleet,
// the same function as `lashscope fleet`); filtered by the logs' tracking verdict; each point links
// to the analyses of its log.
import { api } from "./api.js";
import { timeBandChart } from "./plots.js";
import { badge, errorBox, fmt, h } from "./util.js";

const FILTERS = {
  tracking: { label: "logs that track (poor tracking left out)", poor: false, keep: () => true },
  good: { label: "good tracking only", poor: false, keep: (p) => p.tracking === "good" },
  all: { label: "every log (poor tracking included)", poor: true, keep: () => true },
  poor: { label: "poor tracking only", poor: true, keep: (p) => p.tracking === "poor" },
};

const iv = (q, digits = 1) => (q && q.median != null ? `${fmt(q.median, digits)} [${fmt(q.lo, digits)}, ${fmt(q.hi, digits)}]` : "-");

export async function render(main) {
  const ctrl = new AbortController();
  const filter = h("select", { id: "fleet-filter", "aria-label": "tracking verdict" },
    Object.entries(FILTERS).map(([k, f]) => h("option", { value: k }, f.label)));
  const bandK = h("input", { id: "fleet-band-k", type: "number", min: "0.5", max: "20", step: "0.5", value: "3",
    "aria-label": "band half-width in robust standard deviations", style: "width:5em" });
  const body = h("div", { id: "fleet-body" });
  main.append(h("h1", {}, "Fleet"),
    h("p", { class: "muted" }, "Per vehicle (the driveline's name), from the event store every finished analysis ",
      "writes to: the total lash estimate and the ripple (median measured fluctuation) of each log with its 90 % ",
      "interval, over the log's time, against the fleet band (fleet median ± k × 1.4826 × MAD over the vehicles' ",
      "medians; at least three vehicles). A vehicle outside the band is flagged with the reason, by the rule ",
      "`lashscope fleet` applies. Click a point for the analysis of that log. Definitions: docs/fleet.md."),
    h("div", { class: "toolbar" }, h("label", {}, "logs: ", filter), h("label", {}, " band k = ", bandK)), body);
  const load = async () => {
    const f = FILTERS[filter.value];
    body.replaceChildren(h("p", { class: "muted" }, "loading ..."));
    let rep;
    try {
      rep = await api(`/fleet?band_k=${encodeURIComponent(bandK.value)}&include_poor_tracking=${f.poor}`, { signal: ctrl.signal });
    } catch (err) {
      body.replaceChildren(errorBox(err));
      main.dataset.state = "ready";
      return;
    }
    draw(body, rep, f);
    main.dataset.state = "ready";
  };
  filter.addEventListener("change", load);
  bandK.addEventListener("change", load);
  await load();
  return () => ctrl.abort();
}

function draw(body, rep, f) {
  const flagged = new Set(rep.flagged);
  const pt = rep.poor_tracking || {};
  const rows = rep.vehicles.map((v) => h("tr", { dataset: { vehicle: v.vehicle }, class: flagged.has(v.vehicle) ? "flagged" : null },
    h("td", {}, h("a", { href: "#/fleet", onclick: (e) => {
      e.preventDefault(); // the hash is the router's: scroll to the vehicle's card instead
      document.getElementById(`fleet-${v.vehicle}`)?.scrollIntoView();
    } }, v.vehicle)),
    h("td", { class: "num" }, v.logs), h("td", { class: "num" }, v.events),
    h("td", { class: "num" }, iv(v.total_lash_deg, 2)), h("td", { class: "num" }, iv(v.ripple_rpm, 1)),
    h("td", { class: "num" }, iv(v.gap_open_time_ms, 1)),
    h("td", { class: "wrap" }, v.flags.length ? [badge("poor"), " outlier: ", v.flags.join("; ")] : badge("good"))));
  const band = (q) => rep.bands?.[q] || null;
  const bandText = (q, unit) => (band(q) ? `fleet band ${fmt(band(q).lo, 2)} to ${fmt(band(q).hi, 2)} ${unit}` : "no fleet band (fewer than three vehicles)");
  body.replaceChildren(
    h("section", { class: "card" }, h("h2", {}, `Vehicles (${rep.vehicles.length}), ${rep.flagged.length} flagged`),
      h("p", { class: "muted", id: "fleet-poor" }, `${pt.events || 0} events of ${pt.logs || 0} logs track poorly: `,
        pt.included ? "included in the figures." : "left out of the figures."),
      rep.vehicles.length ? h("div", { class: "scroll" }, h("table", { id: "fleet-table" }, h("thead", {}, h("tr", {},
        ["vehicle", "logs", "events", "total lash (deg) [90 %]", "ripple (rpm) [90 %]", "gap-open time (ms) [90 %]", "fleet band"]
          .map((c) => h("th", {}, c)))), h("tbody", {}, rows)))
        : h("p", { class: "muted" }, "no vehicle has events with metrics under this filter")),
    ...rep.vehicles.map((v) => {
      const points = (v.per_log || []).filter(f.keep).filter((p) => p.time);
      const href = (p) => (p.analyses?.length ? `#/analysis/${encodeURIComponent(p.analyses[0].id)}` : null);
      const chartRows = (q) => points.map((p) => ({ t: Date.parse(p.time), value: p[q].median, lo: p[q].lo, hi: p[q].hi,
        flagged: flagged.has(v.vehicle), href: href(p), label: `${p.log_name} (${p.tracking || "unknown"} tracking)` }));
      const undated = (v.per_log || []).filter(f.keep).length - points.length;
      return h("section", { class: "card fleet-vehicle", id: `fleet-${v.vehicle}`, dataset: { vehicle: v.vehicle, points: points.length } },
        h("h2", {}, v.vehicle, " ", flagged.has(v.vehicle) ? badge("poor") : null, flagged.has(v.vehicle) ? " outlier" : ""),
        v.flags.length ? h("ul", { class: "note" }, v.flags.map((x) => h("li", {}, x))) : null,
        points.length ? h("div", { class: "grid" },
          h("div", {}, h("h3", {}, `Total lash, motor-referred (deg): ${bandText("total_lash_deg", "deg")}`),
            timeBandChart({ id: `lash-${v.vehicle}`, rows: chartRows("total_lash_deg"), band: band("total_lash_deg"),
              yLabel: "total lash (deg)" })),
          h("div", {}, h("h3", {}, `Ripple (rpm): ${bandText("ripple_rpm", "rpm")}`),
            timeBandChart({ id: `ripple-${v.vehicle}`, rows: chartRows("ripple_rpm"), band: band("ripple_rpm"),
              yLabel: "median fluctuation (rpm)" })))
          : h("p", { class: "muted" }, "no log of this vehicle with an absolute time passes the filter"),
        undated > 0 ? h("p", { class: "muted" }, `${undated} log(s) without an absolute time are not on the time axis`) : null,
        h("details", {}, h("summary", {}, `Logs (${(v.per_log || []).filter(f.keep).length})`),
          h("ul", { class: "fleet-logs" }, (v.per_log || []).filter(f.keep).map((p) => h("li", {},
            p.time ? `${p.time.slice(0, 19).replace("T", " ")} UTC · ` : "no time · ", `${p.log_name}: `,
            `lash ${iv(p.total_lash_deg, 2)} deg, ripple ${iv(p.ripple_rpm, 1)} rpm, ${p.events} events, tracking `,
            badge(p.tracking || "unknown"), " ",
            p.analyses?.length ? p.analyses.map((a) => h("a", { href: `#/analysis/${encodeURIComponent(a.id)}` }, `${a.vehicle} v${a.version}`))
              : h("span", { class: "muted" }, "(not stored on this server)"))))));
    }));
}
