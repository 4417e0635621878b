// The REST API as the pages use it: JSON requests, uploads with progress, downloads and
// server-sent events, every one carrying the API key the user entered (Authorization: Bearer).
// EventSource cannot send headers, so the live stream is read with fetch() and parsed here.

const KEY = "lashscope.apiKey";

export function apiKey() {
  return localStorage.getItem(KEY) || "";
}

export function setApiKey(key) {
  if (key) localStorage.setItem(KEY, key.trim());
  else localStorage.removeItem(KEY);
}

function headers(extra = {}) {
  const h = { ...extra };
  const key = apiKey();
  if (key) h.Authorization = `Bearer ${key}`;
  return h;
}

export class ApiError extends Error {
  constructor(status, code, detail) {
    super(`${detail} [${code}]`);
    this.status = status;
    this.code = code;
    this.detail = detail;
  }
}

async function failure(r) {
  let body = {};
  try {
    body = await r.json();
  } catch (_) {
    /* not JSON: keep the status text */
  }
  const detail = typeof body.detail === "string" ? body.detail : r.statusText || `HTTP ${r.status}`;
  return new ApiError(r.status, body.code || `http_${r.status}`, detail);
}

// JSON in, JSON (or text) out; errors become ApiError with the service's code.
export async function api(path, { method = "GET", json, signal } = {}) {
  const opts = { method, headers: headers(), signal };
  if (json !== undefined) {
    opts.body = JSON.stringify(json);
    opts.headers["Content-Type"] = "application/json";
  }
  return answer(await fetch(path, opts));
}

// A fetch() response as api() returns it: JSON (or text), ApiError when not ok.
export async function answer(r) {
  if (!r.ok) throw await failure(r);
  if (r.status === 204) return null;
  const type = r.headers.get("content-type") || "";
  return type.includes("json") ? r.json() : r.text();
}

// multipart upload through XMLHttpRequest, the one browser API that reports upload progress.
export function upload(path, fields, onProgress) {
  return new Promise((resolve, reject) => {
    const form = new FormData();
    for (const [k, v] of Object.entries(fields)) form.append(k, v);
    const xhr = new XMLHttpRequest();
    xhr.open("POST", path);
    for (const [k, v] of Object.entries(headers())) xhr.setRequestHeader(k, v);
    xhr.upload.onprogress = (e) => e.lengthComputable && onProgress(e.loaded / e.total, e.loaded, e.total);
    xhr.onload = () => {
      let body = {};
      try {
        body = JSON.parse(xhr.responseText);
      } catch (_) {
        /* keep {} */
      }
      if (xhr.status >= 200 && xhr.status < 300) resolve(body);
      else reject(new ApiError(xhr.status, body.code || `http_${xhr.status}`, body.detail || xhr.statusText));
    };
    xhr.onerror = () => reject(new ApiError(0, "network_error", "the upload did not reach the server"));
    xhr.send(form);
  });
}

// Save a response (CSV, TOML) under `filename` without leaving the page; the key goes in the header.
export async function download(path, filename, accept = "*/*") {
  const r = await fetch(path, { headers: headers({ Accept: accept }) });
  if (!r.ok) throw await failure(r);
  saveBlob(await r.blob(), filename);
}

export function saveBlob(blob, filename) {
  const a = document.createElement("a");
  a.href = URL.createObjectURL(blob);
  a.download = filename;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
}

// Server-sent events over fetch: calls onMessage(eventName, data) per message until `signal` aborts.
export async function streamEvents(path, onMessage, signal) {
  const r = await fetch(path, { headers: headers({ Accept: "text/event-stream" }), signal });
  if (!r.ok) throw await failure(r);
  const reader = r.body.pipeThrough(new TextDecoderStream()).getReader();
  let buf = "";
  for (;;) {
    const { value, done } = await reader.read();
    if (done) return;
    buf += value;
    let cut;
    while ((cut = buf.indexOf("\n\n")) >= 0) {
      const block = buf.slice(0, cut);
      buf = buf.slice(cut + 2);
      let name = "message";
      const data = [];
      for (const line of block.split("\n")) {
        if (line.startsWith("event:")) name = line.slice(6).trim();
        else if (line.startsWith("data:")) data.push(line.slice(5).trim());
      }
      if (data.length) onMessage(name, JSON.parse(data.join("\n")));
    }
  }
}
