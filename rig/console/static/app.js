// fpp-rig console page: draws what the server sends and calls the JSON API. No rig logic here:
// every decision (what to scan, how to process, what is valid) is the server's.
"use strict";

const clientId = (crypto.randomUUID ? crypto.randomUUID() : String(Math.random()).slice(2));
const $ = (id) => document.getElementById(id);
const state = { status: null, result: null, values: null, lastFrameAt: null, timings: [], frames: 0, capture: null };
window.consoleState = state; // read by the browser tests (timings, frame counts)

// ------------------------------------------------------------------ API calls and errors
async function api(method, path, body) {
  const options = { method, headers: { "X-Console-Client": clientId } };
  if (body !== undefined) {
    options.headers["Content-Type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  const response = await fetch(path, options);
  const text = await response.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (e) { data = { error: text }; }
  if (!response.ok) {
    const message = (data && (data.error || (typeof data.detail === "string" ? data.detail : JSON.stringify(data.detail)))) || response.statusText;
    showError(message);
    throw new Error(message);
  }
  return data;
}

function showError(message) {
  $("error-text").textContent = message;
  $("error").hidden = false;
}
$("error-close").onclick = () => { $("error").hidden = true; };

// ------------------------------------------------------------------ views
document.querySelectorAll("nav button").forEach((button) => {
  button.onclick = () => showView(button.dataset.view);
});
function showView(name) {
  document.querySelectorAll("nav button").forEach((b) => b.classList.toggle("active", b.dataset.view === name));
  document.querySelectorAll(".view").forEach((v) => v.classList.toggle("active", v.id === "view-" + name));
  if (name === "captures") loadCaptures();
  if (name === "result" && window.Plotly && state.result) Plotly.Plots.resize($("result-3d"));
}

// ------------------------------------------------------------------ events websocket
function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const socket = new WebSocket(`${scheme}://${location.host}/api/events?client=${clientId}`);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => socket.send(JSON.stringify({ live: true }));
  socket.onclose = () => { $("state").textContent = "disconnected"; setTimeout(connect, 1000); };
  socket.onmessage = (msg) => {
    if (typeof msg.data === "string") handle(JSON.parse(msg.data));
    else drawFrame(msg.data);
  };
}

function handle(message) {
  switch (message.type) {
    case "hello": updateStatus(message.status); break;
    case "status": updateStatus(message.status); break;
    case "progress": updateProgress(message); break;
    case "job": updateJob(message.job); break;
    case "result": showResult(message.name, message.summary, message.final); break;
    case "saved": if (state.result && state.result.name === message.name) { state.result.saved = true; renderDownloads(); } break;
    case "error": showError(message.message); break;
    default: if (window.calibrationMessage) window.calibrationMessage(message);
  }
}

// ------------------------------------------------------------------ live view
async function drawFrame(buffer) {
  const view = new DataView(buffer);
  const headerLength = view.getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, headerLength)));
  const blob = new Blob([new Uint8Array(buffer, 4 + headerLength)], { type: "image/jpeg" });
  const bitmap = await createImageBitmap(blob);
  const canvas = $("live-view");
  if (canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
    canvas.width = bitmap.width; canvas.height = bitmap.height;
  }
  canvas.getContext("2d").drawImage(bitmap, 0, 0);
  state.frames += 1;
  canvas.dataset.frame = String(header.frame);
  $("frame-no").textContent = header.frame;
  $("fps").textContent = header.fps.toFixed(1);
  $("mean").textContent = (100 * header.mean).toFixed(1) + " %";
  $("saturation").textContent = (100 * header.saturated_fraction).toFixed(2) + " %";
  $("saturation").classList.toggle("warn", header.saturated_fraction > 0.001);
  $("focus").textContent = header.focus.toFixed(1);
  $("valid").textContent = header.valid_fraction === null ? "(project a fringe)" : (100 * header.valid_fraction).toFixed(1) + " %";
  drawHistogram(header.histogram);
}

function drawHistogram(counts) {
  const canvas = $("histogram");
  const ctx = canvas.getContext("2d");
  const top = Math.max(...counts.slice(0, 255), 1);
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  ctx.fillStyle = "#4a90d9";
  counts.forEach((c, i) => {
    const h = Math.min(1, c / top) * canvas.height;
    ctx.fillStyle = i === 255 && c > 0 ? "#d33" : "#4a90d9";
    ctx.fillRect(i, canvas.height - h, 1, h);
  });
}

$("exposure").onchange = () => api("PUT", "/api/exposure", { exposure_us: Number($("exposure").value) }).catch(() => {});
$("gain").onchange = () => api("PUT", "/api/exposure", { gain: Number($("gain").value) }).catch(() => {});
$("overlay").onchange = () => api("PUT", "/api/live", { overlay: $("overlay").checked }).catch(() => {});
$("live-mode").onchange = () => api("PUT", "/api/live", { view: $("live-mode").value }).catch(() => {});
for (const id of ["projector-pattern", "fringe-frequency", "fringe-phase", "fringe-axis", "grid-pitch"]) {
  $(id).onchange = () => api("PUT", "/api/projector", {
    pattern: $("projector-pattern").value, frequency: Number($("fringe-frequency").value),
    phase_deg: Number($("fringe-phase").value), axis: $("fringe-axis").value, pitch_px: Number($("grid-pitch").value),
  }).catch(() => {});
}
$("calibration").onchange = () => api("PUT", "/api/calibration", { name: $("calibration").value || null }).catch(() => {});

// ------------------------------------------------------------------ status
function setIfIdle(id, value) {
  const el = $(id);
  if (document.activeElement !== el && value !== null && value !== undefined) el.value = value;
}

function updateStatus(status) {
  state.status = status;
  $("state").textContent = status.state + (status.device_error ? " (device error)" : "");
  $("state").className = "state " + status.state;
  setIfIdle("exposure", status.exposure_us);
  setIfIdle("gain", status.gain);
  setIfIdle("projector-pattern", status.projector.pattern);
  $("overlay").checked = status.live.overlay;
  $("live-mode").value = status.live.view;
  $("scan-button").disabled = status.busy;
  $("stop-button").disabled = !(status.busy || status.jobs.length);
  fillSelect($("calibration"), ["", ...status.calibrations], status.calibration || "", (n) => n || "none (phase only)");
  for (const select of document.querySelectorAll("select.correction")) {
    fillSelect(select, status.process_options.correction, select.value || status.process_options.default_correction);
  }
  renderDevices(status);
  if (window.calibrationStatus) window.calibrationStatus(status);
}

function fillSelect(select, values, chosen, label) {
  const key = values.join("\n");
  if (select.dataset.key !== key) {
    select.innerHTML = "";
    for (const v of values) {
      const option = document.createElement("option");
      option.value = v; option.textContent = label ? label(v) : v;
      select.appendChild(option);
    }
    select.dataset.key = key;
  }
  if (document.activeElement !== select) select.value = chosen;
}

function renderDevices(status) {
  const table = $("device-status");
  table.innerHTML = "<tr><th>device</th><th>backend</th><th>state</th><th>driver</th><th>details</th></tr>";
  for (const d of status.devices) {
    const row = table.insertRow();
    for (const v of [d.role, d.backend, d.state, d.name || "-", d.detail]) row.insertCell().textContent = v;
    row.className = d.state;
  }
  $("device-error").textContent = status.device_error ? "Last device error: " + status.device_error : "No device error.";
  $("data-dir").textContent = status.data.root;
  $("rig-config").textContent = status.config;
}

// ------------------------------------------------------------------ scan
$("scan-button").onclick = async () => {
  $("scan-progress").value = 0;
  $("scan-note").textContent = "starting";
  state.lastFrameAt = null;
  try {
    const reply = await api("POST", "/api/scan", { options: { correction: $("scan-correction").value } });
    state.scanJob = reply.job.id;
  } catch (e) { $("scan-note").textContent = e.message; }
};
$("stop-button").onclick = () => api("POST", "/api/stop").catch(() => {});

function updateProgress(message) {
  const e = message.event;
  if (message.kind === "scan" && e.total) {
    $("scan-progress").max = e.total;
    $("scan-progress").value = e.done;
    $("scan-note").textContent = `${e.note || e.task} (${e.done} of ${e.total})`;
    if (e.kind === "step" && e.done >= e.total) state.lastFrameAt = performance.now();
  } else if (message.kind === "process") {
    $("scan-note").textContent = `${e.task}: ${e.note} (${e.done} of ${e.total})`;
  }
}

function updateJob(job) {
  if (window.calibrationJob) window.calibrationJob(job);
  if (job.state === "cancelled") $("scan-note").textContent = `${job.kind} ${job.name} stopped: ${job.error}`;
  else if (job.state === "failed") $("scan-note").textContent = `${job.kind} ${job.name} failed`;
  else if (job.state === "done") $("scan-note").textContent = `${job.kind} ${job.name} done`;
  else if (job.stage === "processing") $("scan-note").textContent = `processing ${job.name}`;
}

// ------------------------------------------------------------------ result
async function showResult(name, summary, final) {
  const started = performance.now();
  const lastFrameAt = state.lastFrameAt;
  state.result = summary;
  $("result-title").textContent = `${name}: ${summary.shows} (${summary.unit})` + (final ? "" : " — quick result, refining");
  const stamp = Date.now();
  const base = `/api/results/${encodeURIComponent(name)}`;
  const valuesReady = fetch(`${base}/values.f32?v=${stamp}`).then(async (r) => ({
    data: new Float32Array(await r.arrayBuffer()), width: Number(r.headers.get("X-Width")), height: Number(r.headers.get("X-Height")),
  }));
  const surfaceReady = api("GET", `${base}/surface`);
  const map = $("height-map");
  const loaded = new Promise((resolve) => { map.onload = resolve; map.onerror = resolve; });
  map.src = `${base}/map.png?v=${stamp}`;
  $("scale-high").textContent = summary.range[1].toFixed(2) + " " + summary.unit;
  $("scale-low").textContent = summary.range[0].toFixed(2) + " " + summary.unit;
  renderFigures(summary);
  renderDownloads();
  showView("result");
  await loaded;
  const mapShown = performance.now();
  state.values = { ...(await valuesReady), unit: summary.unit, name };
  await drawSurface(await surfaceReady);
  const shown = performance.now();
  state.timings.push({
    name, final, map_since_last_frame_ms: lastFrameAt ? mapShown - lastFrameAt : null,
    since_last_frame_ms: lastFrameAt ? shown - lastFrameAt : null, map_ms: mapShown - started, render_ms: shown - started,
  });
  $("view-result").dataset.result = name;
  $("view-result").dataset.final = String(final);
}

async function drawSurface(surface) {
  if (!window.Plotly) return;
  const trace = {
    type: "surface", x: surface.x, y: surface.y, z: surface.z, colorscale: "Turbo", showscale: true,
    colorbar: { title: { text: surface.unit } },
  };
  const layout = {
    margin: { l: 0, r: 0, t: 0, b: 0 },
    scene: { aspectmode: "data", xaxis: { title: { text: "x (" + surface.axis_unit + ")" } },
             yaxis: { title: { text: "y (" + surface.axis_unit + ")" } }, zaxis: { title: { text: surface.unit } } },
  };
  if (surface.axis_unit !== surface.unit) layout.scene.aspectmode = "cube";
  await Plotly.react($("result-3d"), [trace], layout, { responsive: true, displaylogo: false });
}

$("height-map").onmousemove = (event) => {
  const v = state.values;
  if (!v || !v.width) return;
  const rect = event.target.getBoundingClientRect();
  const x = Math.min(v.width - 1, Math.max(0, Math.floor((event.clientX - rect.left) * v.width / rect.width)));
  const y = Math.min(v.height - 1, Math.max(0, Math.floor((event.clientY - rect.top) * v.height / rect.height)));
  const value = v.data[y * v.width + x];
  const el = $("height-readout");
  el.dataset.x = x; el.dataset.y = y; el.dataset.value = Number.isNaN(value) ? "" : String(value);
  el.textContent = `x ${x}, y ${y}: ` + (Number.isNaN(value) ? "no valid value" : `${value.toFixed(2)} ${v.unit}`);
};

function renderFigures(s) {
  const table = $("result-figures");
  const rows = [
    ["valid pixels", s.valid_fraction === null ? "-" : (100 * s.valid_fraction).toFixed(1) + " %"],
    ["height (mm)", s.height_mm ? `min ${s.height_mm.min.toFixed(2)}, median ${s.height_mm.median.toFixed(2)}, max ${s.height_mm.max.toFixed(2)}` : "no calibration: phase only"],
    ["wrapped phase", s.methods.wrapped_phase], ["unwrap", s.methods.unwrap], ["denoise", s.methods.denoise],
    ["correction", s.methods.correction], ["frequencies", (s.methods.frequencies || []).join(", ")],
    ["processing time", s.timings_s.total !== undefined ? s.timings_s.total.toFixed(2) + " s" : "-"],
    ["capture", s.capture], ["calibration", s.calibration || "none"],
  ];
  table.innerHTML = "";
  for (const [k, v] of rows) { const r = table.insertRow(); r.insertCell().textContent = k; r.insertCell().textContent = v; }
}

function renderDownloads() {
  const s = state.result;
  const box = $("downloads");
  box.innerHTML = "";
  if (!s) return;
  if (!s.saved) { box.textContent = "writing files ..."; return; }
  const files = s.shows === "height" ? ["points.ply", "height.npy", "report.json", "preview.png"] : ["phase.npy", "report.json", "preview.png"];
  for (const f of files) {
    const a = document.createElement("a");
    a.href = `/api/results/${encodeURIComponent(s.name)}/files/${f}`;
    a.textContent = f; a.download = `${s.name}-${f}`; a.dataset.testid = "download-" + f;
    box.appendChild(a);
  }
}

// ------------------------------------------------------------------ captures
async function loadCaptures() {
  const [captures, results] = await Promise.all([api("GET", "/api/captures"), api("GET", "/api/results")]);
  const list = $("capture-list");
  list.innerHTML = "";
  for (const c of captures.captures) {
    const li = document.createElement("li");
    li.textContent = c.error ? `${c.name} (unreadable: ${c.error})` : `${c.name} — ${c.scene}, ${c.width}x${c.height}, ${c.frames} frames`;
    li.dataset.name = c.name;
    li.onclick = () => openCapture(c.name);
    if (state.capture === c.name) li.classList.add("selected");
    list.appendChild(li);
  }
  const names = results.results.map((r) => r.name);
  fillSelect($("compare-a"), names, $("compare-a").value || names[0] || "");
  fillSelect($("compare-b"), names, $("compare-b").value || names[1] || names[0] || "");
}

async function openCapture(name) {
  state.capture = name;
  document.querySelectorAll("#capture-list li").forEach((li) => li.classList.toggle("selected", li.dataset.name === name));
  const info = await api("GET", `/api/captures/${encodeURIComponent(name)}`);
  $("capture-title").textContent = name;
  const m = info.manifest;
  $("capture-info").textContent = `scene ${m.scene}, created ${m.created_utc}\n${m.camera.width}x${m.camera.height}, ${m.patterns.length} patterns, complete: ${m.complete}`;
  $("reprocess").disabled = false;
  const list = $("capture-results");
  list.innerHTML = "";
  for (const r of info.results) {
    const li = document.createElement("li");
    li.textContent = r;
    li.onclick = async () => showResult(r, await api("GET", `/api/results/${encodeURIComponent(r)}`), true);
    list.appendChild(li);
  }
}

$("reprocess").onclick = async () => {
  if (!state.capture) return;
  await api("POST", "/api/process", {
    capture: state.capture,
    options: { unwrap: $("opt-unwrap").value, denoise: $("opt-denoise").value, correction: $("opt-correction").value },
  }).catch(() => {});
};

$("compare-button").onclick = async () => {
  const a = $("compare-a").value, b = $("compare-b").value;
  if (!a || !b) return;
  const figures = await api("GET", `/api/compare?a=${encodeURIComponent(a)}&b=${encodeURIComponent(b)}`).catch(() => null);
  if (!figures) return;
  const stamp = Date.now();
  $("compare-img-a").src = `/api/results/${encodeURIComponent(a)}/map.png?v=${stamp}`;
  $("compare-img-b").src = `/api/results/${encodeURIComponent(b)}/map.png?v=${stamp}`;
  $("compare-diff").src = `/api/compare.png?a=${encodeURIComponent(a)}&b=${encodeURIComponent(b)}&v=${stamp}`;
  $("compare-cap-a").textContent = a;
  $("compare-cap-b").textContent = b;
  $("compare-cap-diff").textContent = `${a} − ${b}`;
  $("compare-figures").textContent = figures.rms === undefined ? "no pixel valid in both"
    : `rms ${figures.rms.toFixed(3)} ${figures.unit}, max |d| ${figures.max_abs.toFixed(3)} ${figures.unit}, mean ${figures.mean.toFixed(3)} ${figures.unit}`;
};

connect();

// ------------------------------------------------------------------ calibration wizard
(function calibrationWizard() {
  const box = $("calibration-wizard");
  box.innerHTML = `
    <fieldset><legend>New calibration</legend>
      <label>name <input id="cal-name" data-testid="calibration-name" placeholder="cal-<time>"></label>
      <label>plane heights (mm) <input id="cal-heights" value="25, 50, 100, 150"></label>
      <label>board views <input id="cal-views" type="number" min="0" value="6"></label>
      <label>model <select id="cal-model" data-testid="calibration-model">
        <option value="reference-plane">reference plane</option>
        <option value="polynomial">polynomial</option>
        <option value="stereo">stereo (real rig)</option>
      </select></label>
      <label>projector gamma ramp first (levels; 0: none) <input id="cal-gamma" data-testid="calibration-gamma"
        type="number" min="0" value="0"></label>
      <button id="cal-start" data-testid="calibration-start" class="primary">Start</button>
    </fieldset>
    <div id="cal-prompt" data-testid="calibration-prompt" class="error" hidden><span></span>
      <button id="cal-done" data-testid="calibration-done">Done</button></div>
    <ol id="cal-steps" data-testid="calibration-steps" class="wizard-steps"></ol>
    <progress id="cal-progress" max="1" value="0"></progress>
    <pre id="cal-result" data-testid="calibration-result" class="info"></pre>`;
  $("cal-start").onclick = async () => {
    $("cal-steps").innerHTML = ""; $("cal-result").textContent = "";
    const heights = $("cal-heights").value.split(",").map(Number);
    delete $("cal-result").dataset.done;
    await api("POST", "/api/calibrate", { name: $("cal-name").value || null, heights_mm: heights,
      board_views: Number($("cal-views").value), model: $("cal-model").value,
      gamma_levels: Number($("cal-gamma").value) }).catch(() => {});
  };
  $("cal-done").onclick = async () => { $("cal-prompt").hidden = true; await api("POST", "/api/calibrate/answer").catch(() => {}); };
  const showPrompt = (prompt) => {
    if (prompt) $("cal-prompt").querySelector("span").textContent = prompt.text;
    $("cal-prompt").hidden = !prompt;
  };
  const finishSteps = (className) => {
    document.querySelectorAll("#cal-steps li.current").forEach((li) => { li.className = className; });
  };
  window.calibrationMessage = (m) => {
    if (m.type === "prompt") showPrompt(m);
    if (m.type === "calibration") {
      finishSteps("done");
      const figure = (label, value, unit) => (value === null || value === undefined ? "" : `${label} = ${Number(value).toPrecision(7)} ${unit}`);
      $("cal-result").textContent = `${m.name}: ${m.model}\n` + [figure("l0", m.l0_mm, "mm"), figure("d0", m.d0_mm, "mm"),
        figure("f0", m.f0_per_mm, "/mm")].filter(Boolean).join(", ") + "\n" + m.lines.join("\n");
      $("cal-result").dataset.done = "true";
    }
  };
  window.calibrationStatus = (status) => showPrompt(status.prompt); // also a prompt waiting when the page opened
  window.calibrationJob = (job) => {
    if (job.kind !== "calibrate") return;
    if (job.state === "failed" || job.state === "cancelled") {
      finishSteps("failed");
      showPrompt(null);
      $("cal-result").textContent = `${job.name} ${job.state}: ${job.error}`;
    }
  };
  const previous = updateProgress;
  updateProgress = (message) => {
    if (message.kind !== "calibrate") return previous(message);
    const e = message.event;
    if (e.total) { $("cal-progress").max = e.total; $("cal-progress").value = e.done; }
    if (e.kind === "message") {
      document.querySelectorAll("#cal-steps li").forEach((li) => { li.className = "done"; });
      const li = document.createElement("li"); li.textContent = e.note; li.className = "current";
      $("cal-steps").appendChild(li);
    }
  };
})();
