// The Result view: colour-mapped map, hover read-out, 3-D point cloud, key figures and downloads.
// Any tab shows the newest result; only the tab whose job made it switches to this view. The map,
// its colour bar, the cloud's colours and the figures table share one range (the server's).
import { $, api, showView } from "./api.js";
import { CloudView, fetchCloud } from "./cloud.js";
import { showExposureMap } from "./setup.js";

const shown = { summary: null, values: null, calls: 0 };
let cloudView = null;

export async function showResult(name, summary, final, { focus = false, lastFrameAt = null } = {}) {
  const started = performance.now();
  const call = ++shown.calls; // a newer result (the final after the quick one) supersedes this one
  shown.summary = summary;
  $("result-title").textContent = `${name}: ${summary.shows} (${summary.unit})` + (final ? "" : " — quick result, refining");
  const stamp = Date.now();
  const base = `/api/results/${encodeURIComponent(name)}`;
  const valuesReady = fetch(`${base}/values.f32?v=${stamp}`).then(async (r) => ({
    data: new Float32Array(await r.arrayBuffer()), width: Number(r.headers.get("X-Width")), height: Number(r.headers.get("X-Height")),
  }));
  // the quick result's map only: its 3-D view would hold up the corrected result, which follows at once
  const cloudReady = final ? fetchCloud(`${base}/cloud.bin?v=${stamp}`).catch(() => null) : Promise.resolve(undefined);
  const map = $("height-map");
  const loaded = new Promise((resolve) => { map.onload = resolve; map.onerror = resolve; });
  map.src = `${base}/map.png?v=${stamp}`;
  for (const [where, value] of [["scale-high", summary.range[1]], ["scale-low", summary.range[0]],
    ["cloud-high", summary.range[1]], ["cloud-low", summary.range[0]]]) $(where).textContent = formatValue(value);
  $("cloud-unit").textContent = summary.unit;
  renderFigures(summary);
  renderDownloads();
  showExposureMap(name, summary);
  if (focus) showView("result");
  await loaded;
  if (call !== shown.calls) return;
  const mapShown = performance.now();
  const view = $("view-result");
  if (!final) view.dataset.quickMapSinceLastFrameMs = lastFrameAt ? String(mapShown - lastFrameAt) : "";
  shown.values = { ...(await valuesReady), unit: summary.unit, name };
  const cloud = await cloudReady;
  if (call !== shown.calls) return;
  const drawStarted = performance.now();
  if (cloud !== undefined) drawCloud(cloud);
  else clearCloud("3-D view: when the corrected result is in");
  const done = performance.now();
  view.dataset.result = name;
  view.dataset.final = String(final);
  view.dataset.mapMs = String(mapShown - started);
  view.dataset.renderMs = String(done - started);
  view.dataset.drawMs = String(done - drawStarted);
  view.dataset.points = String(cloud ? cloud.count : 0);
  view.dataset.mapSinceLastFrameMs = lastFrameAt ? String(mapShown - lastFrameAt) : "";
  view.dataset.sinceLastFrameMs = lastFrameAt ? String(done - lastFrameAt) : "";
}

export function resultSaved(name) {
  if (shown.summary && shown.summary.name === name) { shown.summary.saved = true; renderDownloads(); }
}

export async function openResult(name, options = {}) {
  showResult(name, await api("GET", `/api/results/${encodeURIComponent(name)}`), true, options);
}

// The cloud in the 3-D view (points from the server, coloured as the map).
function drawCloud(cloud) {
  cloudView = cloudView || new CloudView($("result-cloud"));
  if (!cloud || !cloudView.ready) { $("cloud-info").textContent = cloudView.ready ? "no 3-D view" : "no WebGL in this browser"; return; }
  cloudView.setCloud(cloud.positions, cloud.colours);
  const every = cloud.step > 1 ? `, every ${cloud.step}${cloud.step === 2 ? "nd" : cloud.step === 3 ? "rd" : "th"} row and column` : "";
  const axes = cloud.axisUnit === "px" ? "x, y in pixels, phase as relief" : `x, y, z in ${cloud.axisUnit}`;
  $("cloud-info").textContent = `${cloud.count.toLocaleString("en")} points${every}; ${axes}`;
}

// No cloud (yet): an empty view rather than the previous result's points beside this map.
function clearCloud(note) {
  if (cloudView && cloudView.ready) cloudView.setCloud(new Float32Array(0), new Uint8Array(0));
  $("cloud-info").textContent = note;
}

// A colour-bar or table figure: the same digits wherever the range is shown.
export function formatValue(value) { return value.toFixed(2); }

function readout(event) {
  const v = shown.values;
  if (!v || !v.width) return;
  const rect = event.target.getBoundingClientRect();
  const x = Math.min(v.width - 1, Math.max(0, Math.floor((event.clientX - rect.left) * v.width / rect.width)));
  const y = Math.min(v.height - 1, Math.max(0, Math.floor((event.clientY - rect.top) * v.height / rect.height)));
  const value = v.data[y * v.width + x];
  const el = $("height-readout");
  el.dataset.x = x; el.dataset.y = y; el.dataset.value = Number.isNaN(value) ? "" : String(value);
  el.textContent = `x ${x}, y ${y}: ` + (Number.isNaN(value) ? "no valid value" : `${value.toFixed(2)} ${v.unit}`);
}

function renderFigures(s) {
  const rows = [
    ["valid pixels", s.valid_fraction === null ? "-" : (100 * s.valid_fraction).toFixed(1) + " %"],
    ["height (mm)", s.height_mm ? `min ${formatValue(s.height_mm.min)}, median ${formatValue(s.height_mm.median)}, max ${formatValue(s.height_mm.max)}` : "no calibration: phase only"],
    ["colour range", `${formatValue(s.range[0])} .. ${formatValue(s.range[1])} ${s.unit}`],
    ["wrapped phase", s.methods.wrapped_phase], ["unwrap", s.methods.unwrap], ["denoise", s.methods.denoise],
    ["correction", s.methods.correction], ["frequencies", (s.methods.frequencies || []).join(", ")],
    ["processing time", s.timings_s.total !== undefined ? s.timings_s.total.toFixed(2) + " s" : "-"],
    ["capture", s.capture], ["calibration", s.calibration || "none"],
  ];
  const table = $("result-figures");
  table.replaceChildren();
  for (const [k, v] of rows) { const r = table.insertRow(); r.insertCell().textContent = k; r.insertCell().textContent = v; }
}

// The files the saved result holds, as the server lists them (its result store names every file once).
async function renderDownloads() {
  const s = shown.summary;
  const box = $("downloads");
  box.replaceChildren();
  if (!s) return;
  if (!s.saved) { box.textContent = "writing files ..."; return; }
  const name = s.name;
  const reply = await api("GET", `/api/results/${encodeURIComponent(name)}/files`).catch(() => null);
  if (!reply || shown.summary?.name !== name) return;
  box.replaceChildren(...reply.files.map((f) => {
    const a = document.createElement("a");
    a.href = `/api/results/${encodeURIComponent(name)}/files/${encodeURIComponent(f.name)}`;
    a.textContent = f.name; a.download = `${name}-${f.name}`; a.dataset.testid = "download-" + f.name;
    a.type = f.media_type;
    return a;
  }));
  box.dataset.files = reply.files.map((f) => f.name).join(",");
}

export function bindResult() {
  $("height-map").onmousemove = readout;
  document.addEventListener("view", (event) => { if (event.detail === "result" && cloudView) cloudView.draw(); });
  window.addEventListener("resize", () => { if (cloudView) cloudView.draw(); });
}
