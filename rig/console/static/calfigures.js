// What the chosen calibration found, drawn: each plane's residual and flatness, the projector gamma
// curve (measured levels and the fitted power law), and every board view with its detected
// corners and reprojection residuals (drawn by the server: /api/calibrations/NAME/board/VIEW.png).
import { $, request } from "./api.js";

async function plot(id, traces, layout) {
  const box = $(id);
  box.hidden = !traces;
  if (!traces || !window.Plotly) return;
  await window.Plotly.react(box, traces, { margin: { l: 60, r: 10, t: 30, b: 45 }, height: 260, ...layout },
    { displaylogo: false, responsive: true });
}

function planes(p) {
  if (!p || !p.residuals_mm) return plot("calfig-planes", null);
  const labels = p.heights_mm.map((h) => `${h} mm`);
  return plot("calfig-planes", [
    { type: "bar", name: "height residual", x: labels, y: p.residuals_mm, marker: { color: "#1f6fd1" } },
    { type: "bar", name: "flatness RMS", x: labels, y: p.flatness_rms_mm || [], marker: { color: "#ef6c00" } },
  ], { title: { text: "planes: residual of the fit and flatness (mm)" }, barmode: "group", yaxis: { title: { text: "mm" } } });
}

function gamma(g) {
  $("calfig-gamma").dataset.gamma = g?.gamma ?? "";
  if (!g || !g.levels) return plot("calfig-gamma", null);
  const xs = Array.from({ length: 101 }, (_, i) => i / 100);
  return plot("calfig-gamma", [
    { type: "scatter", mode: "markers", name: "measured", x: g.levels, y: g.responses },
    { type: "scatter", mode: "lines", name: `fit: gamma ${g.gamma.toFixed(3)}`, x: xs, y: xs.map((x) => g.offset + g.gain * x ** g.gamma) },
  ], { title: { text: `projector gamma ${g.gamma.toFixed(3)} (fit RMS ${g.residual_rms.toFixed(2)} grey levels)` },
    xaxis: { title: { text: "projector level" } }, yaxis: { title: { text: "camera grey level" } } });
}

function boards(name, views, camera) {
  const box = $("calfig-boards");
  box.replaceChildren();
  $("calfig-boards-title").hidden = views.length === 0;
  if (camera) $("calfig-boards-title").textContent = `board views: corners (green lit, grey unlit), residuals x20 (red); camera fit ${camera.reprojection_rms_px.toFixed(3)} px RMS`;
  for (const view of views) {
    const figure = document.createElement("figure");
    const img = document.createElement("img");
    const caption = document.createElement("figcaption");
    figure.dataset.view = view;
    figure.append(img, caption);
    box.appendChild(figure);
    fetch(`/api/calibrations/${encodeURIComponent(name)}/board/${encodeURIComponent(view)}.png`).then(async (r) => {
      const found = JSON.parse(r.headers.get("X-Figures") || "{}");
      caption.textContent = !r.ok ? `${view}: not readable` : !found.found ? `${view}: no board found`
        : `${view}: ${found.lit} of ${found.corners} corners lit` + (found.rms_px !== undefined ? `, reprojection ${found.rms_px.toFixed(3)} px RMS (max ${found.max_px.toFixed(3)})` : "");
      if (r.ok) img.src = URL.createObjectURL(await r.blob());
      figure.dataset.rms = found.rms_px ?? "";
    });
  }
}

export async function showCalibrationFigures(name) {
  $("calfig-title").textContent = name ? `What ${name} found` : "";
  $("calfig").hidden = !name;
  if (!name) return;
  const f = await request("GET", `/api/calibrations/${encodeURIComponent(name)}/figures`).catch(() => null);
  if (!f || f.calibration !== name) return;
  $("calfig").dataset.calibration = name;
  $("calfig-note").textContent = [f.model && `model ${f.model}`, !f.planes && "no plane heights recorded",
    !f.gamma && "no gamma ramp", f.board_views.length === 0 && "no board views kept"].filter(Boolean).join("; ");
  await Promise.all([planes(f.planes), gamma(f.gamma)]);
  boards(name, f.board_views, f.camera);
}
