// The analysis view's tolerance and sensitivity card: where each measured event sits in the Monte
// Carlo band of the predicted fluctuation over the vehicle's tolerances (GET/POST
// /analyses/<id>/tolerance), and the gap-sensitivity bars of the analysed vehicle version (GET/POST
// /vehicles/<name>/gap-sensitivity). Both are background jobs started from here, with their progress;
// opening the page only reads what was computed before.
import { api } from "./api.js";
import { bandChart, barChart } from "./plots.js";
import { errorBox, fmt, h, progressBar, sleep } from "./util.js";

const N = 200;

export function toleranceCard(id, rec, signal) {
  const tolOut = h("div", { id: "tolerance-out" });
  const sensOut = h("div", { id: "sensitivity-out" });
  const tolStart = h("button", { id: "tolerance-start", onclick: () => runTolerance(true) },
    `Compute the tolerance band (${N} variants per event)`);
  const sensStart = h("button", { id: "sensitivity-start", onclick: () => runSensitivity(true) },
    `Compute the gap sensitivity of ${rec.vehicle} v${rec.vehicle_version}`);
  const card = h("section", { class: "card", id: "tolerance-card" },
    h("h2", {}, "Tolerances and gap sensitivity"),
    h("p", { class: "muted" }, "The predicted peak-to-valley fluctuation of each event with every gap and ",
      "tolerance of the vehicle file sampled uniformly (Monte Carlo, fixed seed): a measured value outside the ",
      "5-95 % band is not explained by the vehicle's tolerances. The gap sensitivity is the paper's: the ",
      "impact-induced fluctuation each gap causes per unit of its size."),
    h("div", { class: "toolbar" }, tolStart), tolOut, h("div", { class: "toolbar" }, sensStart), sensOut);

  // start: POST; otherwise read the state first (a read that never starts work, and never a 404)
  async function runTolerance(start) {
    tolStart.disabled = true;
    try {
      let doc;
      if (start) doc = await api(`/analyses/${id}/tolerance?n=${N}`, { method: "POST", signal });
      else {
        const st = await api(`/analyses/${id}/tolerance/status?n=${N}`, { signal });
        if (st.status === "not_started") {
          tolOut.replaceChildren(h("p", { class: "muted" }, "not computed yet for this analysis"));
          tolStart.disabled = false;
          return;
        }
        if (st.status === "failed") throw new Error(`the last tolerance band failed: ${st.error.detail} [${st.error.code}]`);
        doc = st.status === "done" ? await api(`/analyses/${id}/tolerance?n=${N}`, { signal }) : st;
      }
      while (doc.job_id && doc.status !== "done") {
        tolOut.replaceChildren(progressBar(doc.progress || 0, `tolerance band: ${doc.stage || doc.status} ${Math.round(100 * (doc.progress || 0))} %`));
        tolOut.dataset.progress = doc.progress || 0;
        await sleep(700);
        doc = await api(`/analyses/${id}/tolerance?n=${N}`, { signal });
      }
      drawTolerance(doc);
      tolStart.remove();
    } catch (err) {
      tolOut.replaceChildren(errorBox(err));
      tolStart.disabled = false;
    }
  }

  function drawTolerance(doc) {
    const ok = doc.events.filter((e) => !e.error && e.band_rpm);
    const outside = ok.filter((e) => e.measured_fluctuation_rpm < e.band_rpm.p5 || e.measured_fluctuation_rpm > e.band_rpm.p95);
    const rows = ok.map((e) => ({ label: `#${e.index}`, lo: e.band_rpm.p5, mid: e.band_rpm.p50, hi: e.band_rpm.p95,
      nominal: e.nominal_fluctuation_rpm, measured: e.measured_fluctuation_rpm,
      note: `measured at the ${fmt(e.measured_percentile, 0)}th percentile` }));
    tolOut.replaceChildren(...[
      h("p", { id: "tolerance-summary" }, `${ok.length - outside.length} of ${ok.length} events measured inside the predicted `,
        `5-95 % band; ${outside.length} outside${outside.length ? `: ${outside.map((e) => `#${e.index}`).join(", ")}` : ""}. `,
        `${doc.n} variants per event, seed ${doc.seed}; sampled: ${(doc.sampled_fields || []).join(", ") || "-"}.`),
      h("div", { class: "scroll" }, bandChart({ id: "tolerance-chart", rows, yLabel: "fluctuation peak-valley (rpm)",
        width: Math.max(640, Math.min(1300, 30 * rows.length + 80)) })),
      doc.events.some((e) => e.error) ? h("p", { class: "muted" }, "not run: ",
        doc.events.filter((e) => e.error).map((e) => `#${e.index} (${e.error})`).join("; ")) : null].filter(Boolean));
    tolOut.dataset.events = ok.length;
  }

  async function runSensitivity(start) {
    sensStart.disabled = true;
    const base = `/vehicles/${encodeURIComponent(rec.vehicle)}/gap-sensitivity`;
    const path = `${base}?version=${rec.vehicle_version}&compute=false`;
    try {
      let doc;
      if (start) doc = await api(path, { method: "POST", signal });
      else {
        const st = await api(`${base}/status?version=${rec.vehicle_version}`, { signal });
        if (st.status === "not_started") {
          sensOut.replaceChildren(h("p", { class: "muted" }, "not computed yet for this vehicle version"));
          sensStart.disabled = false;
          return;
        }
        if (st.status === "failed") throw new Error(`the last gap sensitivity failed: ${st.error.detail} [${st.error.code}]`);
        doc = st.status === "done" ? await api(path, { signal }) : st;
      }
      while (doc.job_id) {
        sensOut.replaceChildren(progressBar(doc.progress || 0, `gap sensitivity: ${doc.stage || doc.status} ${Math.round(100 * (doc.progress || 0))} %`));
        sensOut.dataset.progress = doc.progress || 0;
        await sleep(700);
        doc = await api(path, { signal });
      }
      drawSensitivity(doc);
      sensStart.remove();
    } catch (err) {
      sensOut.replaceChildren(errorBox(err));
      sensStart.disabled = false;
    }
  }

  function drawSensitivity(doc) {
    const unit = doc.sensitivity_unit;
    const gaps = doc.gaps.map((g) => g.gap);
    sensOut.replaceChildren(
      h("p", { class: "muted" }, doc.sensitivity_definition, ". Scenario: ", doc.scenario, "."),
      h("div", { class: "grid" },
        h("div", {}, h("h3", {}, `Sensitivity per ${unit} of gap`),
          barChart({ id: "sensitivity-chart", categories: gaps, groups: [{ label: `S (per ${unit}, normalised)`, color: "#7b2fbe",
            values: doc.gaps.map((g) => g.sensitivity) }], yLabel: `sensitivity (per ${unit}, half-shaft = 100)`, width: 480 })),
        h("div", {}, h("h3", {}, "Fluctuation with each gap removed or halved (rpm)"),
          barChart({ id: "sensitivity-fluct", categories: gaps, groups: [
            { label: "gap removed", color: "#1f77b4", values: doc.gaps.map((g) => g.removed.fluctuation_rpm) },
            { label: "gap halved", color: "#ff7f0e", values: doc.gaps.map((g) => g.halved.fluctuation_rpm) }],
          ref: { value: doc.nominal.fluctuation_rpm, label: `nominal ${fmt(doc.nominal.fluctuation_rpm, 0)} rpm` },
          yLabel: "fluctuation peak-valley (rpm)", width: 480 }))),
      h("table", { id: "sensitivity-table" }, h("thead", {}, h("tr", {}, ["gap", "size", `sensitivity (per ${unit})`,
        "fluctuation, removed (rpm)", "fluctuation, halved (rpm)"].map((c) => h("th", {}, c)))),
      h("tbody", {}, doc.gaps.map((g) => h("tr", { dataset: { gap: g.gap } }, h("td", {}, g.gap),
        h("td", { class: "num" }, g.clearance_mm != null ? `${fmt(g.clearance_mm, 3)} mm` : `${fmt(g.nominal_rad, 4)} rad`),
        h("td", { class: "num" }, fmt(g.sensitivity, 1)), h("td", { class: "num" }, fmt(g.removed.fluctuation_rpm, 1)),
        h("td", { class: "num" }, fmt(g.halved.fluctuation_rpm, 1)))))));
  }

  // what was computed before: shown at once; nothing starts until a button is pressed
  runTolerance(false);
  runSensitivity(false);
  return card;
}
