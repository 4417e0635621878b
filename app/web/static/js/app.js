// The dashboard's router: #/logs, #/analysis/<id>[/ch=<channels>], #/diagnosis/<id>, #/identify[/<id>],
// #/vehicles, #/fleet, #/live[/<session>].
// Each page module exports render(main, ...params) and may return a cleanup function.
import { apiKey, setApiKey } from "./api.js";
import { errorBox } from "./util.js";

const PAGES = {
  logs: () => import("./logs.js"),
  analysis: () => import("./analysis.js"),
  diagnosis: () => import("./diagnosis.js"),
  identify: () => import("./identify.js"),
  vehicles: () => import("./vehicles.js"),
  fleet: () => import("./fleet.js"),
  live: () => import("./live.js"),
};

let cleanup = null;

async function route() {
  const [name = "logs", ...params] = location.hash.replace(/^#\/?/, "").split("/").filter(Boolean);
  const load = PAGES[name] || PAGES.logs;
  for (const a of document.querySelectorAll("nav a[data-page]")) {
    a.classList.toggle("active", a.dataset.page === name || (name === "analysis" && a.dataset.page === "logs"));
  }
  if (cleanup) cleanup();
  cleanup = null;
  const main = document.getElementById("view");
  main.replaceChildren();
  main.dataset.page = name;
  delete main.dataset.state; // set again by the page once it has drawn
  try {
    performance.mark("route");
    const mod = await load();
    cleanup = (await mod.render(main, ...params.map(decodeURIComponent))) || null;
  } catch (err) {
    main.append(errorBox(err));
  }
}

const input = document.getElementById("api-key");
input.value = apiKey();
document.getElementById("key-form").addEventListener("submit", (e) => {
  e.preventDefault();
  setApiKey(input.value);
  route();
});
window.addEventListener("hashchange", route);
route();
