// The analysis view's first reads, started while the page's own files still load. The server
// inlines this file into the page (app/web/assets.py), so on a cold load of #/analysis/<id> the
// status, the channel list, the whole-log rows and the pedal rows are on their way a few hundred
// ms before the modules have run; analysis.js takes them over (and calls lashscopeFirstReads
// again when the analysis was still running). A plain script without imports: it runs while the
// page is parsed. The key is the one api.js keeps ("lashscope.apiKey" in localStorage).
window.lashscopeFirstReads = (id, maxPoints) => {
  const key = localStorage.getItem("lashscope.apiKey");
  const init = { headers: key ? { Authorization: `Bearer ${key}` } : {} };
  const base = `/analyses/${encodeURIComponent(id)}`;
  const signals = fetch(`${base}/signals`, init);
  const pedal = signals.then((r) => (r.ok ? r.clone().json() : { signals: {} })).then((s) => {
    const name = Object.keys(s.signals).find((n) => n.startsWith("pedal"));
    return name ? { name, rows: fetch(`${base}/signals/${name}?max_points=${maxPoints}`, init) } : null;
  });
  const reads = { id, maxPoints, record: fetch(base, init), signals, speed: fetch(`${base}/speed?max_points=${maxPoints}`, init), pedal };
  for (const p of [reads.record, signals, reads.speed, pedal]) p.catch(() => {}); // taken over, or unused
  return reads;
};

// max_points: two rows per pixel of the chart, whose width is the page's (at most 1500 px) less
// the margins; analysis.js keeps this density for the zooms.
window.lashscopeEarly = (() => {
  const m = /^#\/analysis\/([^/]+)(\/ch=[^/]*)?$/.exec(location.hash);
  const width = Math.max(600, Math.min(document.documentElement.clientWidth, 1500) - 82);
  return m ? window.lashscopeFirstReads(decodeURIComponent(m[1]), Math.min(4000, 2 * width)) : null;
})();
