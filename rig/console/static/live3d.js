// The live 3-D view: each short scan's point cloud as the server sends it (coloured by height over
// that set's range), with the rate of sets shown and the latency from a set's last frame to its
// points being drawn (the server's part, then this page's fetch-free draw).
import { $, api } from "./api.js";
import { CloudView } from "./cloud.js";

let view = null;

// A binary live3d message: header (type live3d, figures) and the cloud's bytes (positions, colours).
export function drawLive3d(header, payload, received) {
  view = view || new CloudView($("live3d-view"));
  const count = header.points;
  const bytes = payload.buffer.slice(payload.byteOffset, payload.byteOffset + payload.byteLength);
  view.setCloud(new Float32Array(bytes, 0, count * 3), new Uint8Array(bytes, count * 12, count * 4), { keepCamera: true });
  const drawn = performance.now();
  const latency = header.latency_ms + (drawn - received);
  const canvas = $("live3d-view");
  canvas.dataset.shown = String(Number(canvas.dataset.shown || 0) + 1);
  canvas.dataset.latencyMs = String(latency);
  canvas.dataset.rateHz = String(header.rate_hz);
  $("live3d-set").textContent = header.set;
  $("live3d-rate").textContent = header.rate_hz.toFixed(1) + " Hz";
  $("live3d-latency").textContent = latency.toFixed(0) + " ms";
  $("live3d-points").textContent = count.toLocaleString("en");
  $("live3d-unit").textContent = header.unit;
  $("live3d-high").textContent = header.range[1].toFixed(2);
  $("live3d-low").textContent = header.range[0].toFixed(2);
  $("live3d-note").textContent = `${header.patterns} patterns a set, ${header.width}x${header.height}, no correction`;
}

export function live3dError(message) { $("live3d-note").textContent = message.error; }

// The status says whether live 3-D is on (any page may switch it): show the cloud or the camera.
export function showLive3d(status) {
  const on = Boolean(status.live_3d && status.live_3d.on);
  $("live3d-toggle").checked = on;
  $("live3d").hidden = !on;
  $("live-view").hidden = on;
  $("live-figures").hidden = on;
  if (on && view) view.draw();
}

export function bindLive3d() {
  $("live3d-toggle").onchange = () => api("PUT", "/api/live3d", { on: $("live3d-toggle").checked })
    .catch((e) => { $("live3d-toggle").checked = false; $("live3d-note").textContent = e.message; });
}
