// The live view: camera frames and their figures, camera and projector settings, device status.
import { $, api, fillSelect } from "./api.js";
import { sendCameraSetting } from "./fields.js";
import { drawLive3d } from "./live3d.js";

// A binary message: a 4-byte header length, the JSON header, then a live frame's JPEG or a live 3-D cloud.
export function binaryMessage(buffer) {
  const received = performance.now();
  const headerLength = new DataView(buffer).getUint32(0, true);
  const header = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 4, headerLength)));
  const payload = new Uint8Array(buffer, 4 + headerLength);
  if (header.type === "live3d") drawLive3d(header, payload, received);
  else drawFrame(header, payload);
}

async function drawFrame(header, payload) {
  const bitmap = await createImageBitmap(new Blob([payload], { type: "image/jpeg" }));
  const canvas = $("live-view");
  if (canvas.width !== bitmap.width || canvas.height !== bitmap.height) {
    canvas.width = bitmap.width; canvas.height = bitmap.height;
  }
  canvas.getContext("2d").drawImage(bitmap, 0, 0);
  canvas.dataset.frame = String(header.frame);
  canvas.dataset.shown = String(Number(canvas.dataset.shown || 0) + 1);
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
  counts.forEach((c, i) => {
    const h = Math.min(1, c / top) * canvas.height;
    ctx.fillStyle = i === 255 && c > 0 ? "#d33" : "#4a90d9";
    ctx.fillRect(i, canvas.height - h, 1, h);
  });
}

function setIfIdle(id, value) {
  const el = $(id);
  if (document.activeElement !== el && value !== null && value !== undefined) el.value = value;
}

export function showSettings(status) {
  setIfIdle("exposure", status.exposure_us);
  setIfIdle("gain", status.gain);
  setIfIdle("projector-pattern", status.projector.pattern);
  setIfIdle("fringe-frequency", status.projector.frequency);
  setIfIdle("fringe-phase", status.projector.phase_deg);
  setIfIdle("fringe-axis", status.projector.axis);
  setIfIdle("grid-pitch", status.projector.pitch_px);
  $("overlay").checked = status.live.overlay;
  $("live-mode").value = status.live.view;
  fillSelect($("calibration"), ["", ...status.calibrations], status.calibration || "", (n) => n || "none (phase only)");
  renderDevices(status);
}

function renderDevices(status) {
  const table = $("device-status");
  table.replaceChildren();
  const header = table.insertRow();
  for (const title of ["device", "backend", "state", "driver", "details"]) {
    const th = document.createElement("th"); th.textContent = title; header.appendChild(th);
  }
  for (const d of status.devices) {
    const row = table.insertRow();
    for (const v of [d.role, d.backend, d.state, d.name || "-", d.detail]) row.insertCell().textContent = v;
    row.className = d.state;
  }
  $("device-error").textContent = status.device_error ? "Last device error: " + status.device_error : "No device error.";
  $("data-dir").textContent = status.data.root;
  $("rig-config").textContent = status.config;
}

export function bindSettings() {
  const put = (path, body) => api("PUT", path, body).catch(() => {});
  $("exposure").onchange = () => sendCameraSetting($("exposure"), "exposure_us", "an exposure time in microseconds (1 to 10000000)");
  $("gain").onchange = () => sendCameraSetting($("gain"), "gain", "a gain of 0 or more");
  $("overlay").onchange = () => put("/api/live", { overlay: $("overlay").checked });
  $("live-mode").onchange = () => put("/api/live", { view: $("live-mode").value });
  for (const id of ["projector-pattern", "fringe-frequency", "fringe-phase", "fringe-axis", "grid-pitch"]) {
    $(id).onchange = () => put("/api/projector", {
      pattern: $("projector-pattern").value, frequency: Number($("fringe-frequency").value),
      phase_deg: Number($("fringe-phase").value), axis: $("fringe-axis").value, pitch_px: Number($("grid-pitch").value),
    });
  }
  $("calibration").onchange = () => put("/api/calibration", { name: $("calibration").value || null });
}
