// Measuring on the shown result: line profile, point-to-point distance, plane fit (flatness and the
// height above the plane), histogram and region statistics. Two clicks on the map (or the four
// coordinate fields) give the line, the two points or the region's corners; the numbers come from
// the server (/api/results/NAME/measure/TOOL), which also writes the CSV the link downloads.
import { $, request } from "./api.js";

const TOOLS = {
  profile: { shape: "line", hint: "click the start and the end of the line", whole: false },
  distance: { shape: "line", hint: "click the two points", whole: false },
  plane: { shape: "box", hint: "click two corners of the region to fit (Whole map: all of it)", whole: true },
  histogram: { shape: "box", hint: "click two corners of the region (Whole map: all of it)", whole: true },
  roi: { shape: "box", hint: "click two corners of the region (Whole map: all of it)", whole: true },
};
const FIELDS = ["x0", "y0", "x1", "y1"];
let picks = []; // map pixels picked since the last measurement
let overlay = null;

const resultName = () => $("view-result").dataset.result || "";
const tool = () => $("measure-tool").value;

function fmt(value, digits = 3) {
  return value === null || value === undefined ? "-" : Number(value).toFixed(digits);
}

function mapPixel(event) {
  const map = $("height-map");
  const rect = map.getBoundingClientRect();
  const w = map.naturalWidth, h = map.naturalHeight;
  return [
    Math.min(w - 1, Math.max(0, Math.floor((event.clientX - rect.left) * w / rect.width))),
    Math.min(h - 1, Math.max(0, Math.floor((event.clientY - rect.top) * h / rect.height))),
  ];
}

function corners() {
  const values = FIELDS.map((f) => $("measure-" + f).value.trim());
  return values.every((v) => v !== "") ? values.map(Number) : null;
}

function setCorners(values) {
  FIELDS.forEach((f, i) => { $("measure-" + f).value = values ? String(values[i]) : ""; });
}

// The picked line, points or box over the map, in the map's displayed size.
function drawOverlay() {
  const map = $("height-map");
  overlay.style.left = map.offsetLeft + "px";
  overlay.style.top = map.offsetTop + "px";
  overlay.width = map.clientWidth;
  overlay.height = map.clientHeight;
  const ctx = overlay.getContext("2d");
  ctx.clearRect(0, 0, overlay.width, overlay.height);
  if (!map.naturalWidth) return;
  const sx = overlay.width / map.naturalWidth, sy = overlay.height / map.naturalHeight;
  const c = corners();
  const points = picks.length === 1 ? [picks[0]] : c ? [[c[0], c[1]], [c[2], c[3]]] : [];
  ctx.strokeStyle = "#fff"; ctx.fillStyle = "#fff"; ctx.lineWidth = 2;
  const at = ([x, y]) => [(x + 0.5) * sx, (y + 0.5) * sy];
  for (const p of points) { const [x, y] = at(p); ctx.beginPath(); ctx.arc(x, y, 3, 0, 2 * Math.PI); ctx.fill(); }
  if (points.length < 2) return;
  const [a, b] = points.map(at);
  ctx.beginPath();
  if (TOOLS[tool()].shape === "line") { ctx.moveTo(...a); ctx.lineTo(...b); }
  else ctx.rect(Math.min(a[0], b[0]), Math.min(a[1], b[1]), Math.abs(b[0] - a[0]), Math.abs(b[1] - a[1]));
  ctx.stroke();
}

function pick(event) {
  if (!resultName()) return;
  const p = mapPixel(event);
  picks = picks.length >= 2 ? [p] : [...picks, p];
  if (picks.length === 2) { setCorners([...picks[0], ...picks[1]]); measure(); }
  else { setCorners(null); $("measure-hint").textContent = `(${p[0]}, ${p[1]}); ` + TOOLS[tool()].hint; }
  drawOverlay();
}

function query(extra = {}) {
  const c = corners();
  const params = new URLSearchParams(extra);
  if (c) FIELDS.forEach((f, i) => params.set(f, String(c[i])));
  return params;
}

function figureRows(f) {
  const u = f.unit, lu = f.lateral_unit;
  switch (f.tool) {
    case "profile":
      return [["samples", `${f.samples} (${f.valid} valid)`, f.samples], ["length", `${fmt(f.length)} ${lu}`, f.length],
        ["min", `${fmt(f.min)} ${u}`, f.min], ["max", `${fmt(f.max)} ${u}`, f.max], ["mean", `${fmt(f.mean)} ${u}`, f.mean]];
    case "distance":
      return [
        ["point 1", `(${f.points[0].col}, ${f.points[0].row}): ${fmt(f.points[0].value)} ${u}`, f.points[0].value],
        ["point 2", `(${f.points[1].col}, ${f.points[1].row}): ${fmt(f.points[1].value)} ${u}`, f.points[1].value],
        ["lateral distance", `${fmt(f.lateral_distance)} ${lu}`, f.lateral_distance],
        ["rise", `${fmt(f.rise)} ${u} (point 2 - point 1)`, f.rise],
        ["3-D distance", f.distance_3d === null ? "- (lateral and height units differ)" : `${fmt(f.distance_3d)} ${u}`, f.distance_3d],
      ];
    case "plane":
      return [["points fitted", String(f.points), f.points], ["flatness", `${fmt(f.flatness)} ${u} (peak to valley of the distances)`, f.flatness],
        ["rms", `${fmt(f.rms)} ${u}`, f.rms], ["tilt", f.tilt_deg === null ? "-" : `${fmt(f.tilt_deg)} deg`, f.tilt_deg],
        ["distances", f.orthogonal ? "along the normal" : "vertical (phase over pixels)", null]];
    case "histogram":
      return [["valid pixels", String(f.valid), f.valid], ["bins", String(f.bins), f.bins],
        ["range", `${fmt(f.edges[0])} .. ${fmt(f.edges[f.edges.length - 1])} ${u}`, null], ["mode", `${fmt(f.mode)} ${u}`, f.mode]];
    default:
      return [["valid", `${f.valid} of ${f.pixels} (${fmt(100 * f.valid_fraction, 1)} %)`, f.valid_fraction],
        ["mean", `${fmt(f.mean)} ${u}`, f.mean], ["std", `${fmt(f.std)} ${u}`, f.std], ["median", `${fmt(f.median)} ${u}`, f.median],
        ["min", `${fmt(f.min)} ${u}`, f.min], ["max", `${fmt(f.max)} ${u}`, f.max],
        ["peak to valley", `${fmt(f.peak_to_valley)} ${u}`, f.peak_to_valley],
        ["size", `${fmt(f.width, 1)} x ${fmt(f.height, 1)} ${lu}`, null]];
  }
}

function showFigures(f) {
  const table = $("measure-figures");
  table.replaceChildren();
  for (const [label, text, value] of figureRows(f)) {
    const row = table.insertRow();
    row.insertCell().textContent = label;
    const cell = row.insertCell();
    cell.textContent = text;
    cell.dataset.testid = "measure-" + label.toLowerCase().replace(/[^a-z0-9]+/g, "-").replace(/^-|-$/g, "");
    cell.dataset.value = value === null || value === undefined ? "" : String(value);
  }
  table.dataset.tool = f.tool;
}

async function drawChart(f) {
  const chart = $("measure-chart");
  chart.hidden = !(f.tool === "profile" || f.tool === "histogram");
  if (chart.hidden || !window.Plotly) return;
  const trace = f.tool === "profile"
    ? { type: "scatter", mode: "lines", x: f.distance, y: f.value, connectgaps: false }
    : { type: "bar", x: f.edges.slice(0, -1).map((e, i) => (e + f.edges[i + 1]) / 2), y: f.counts, marker: { color: "#1f6fd1" } };
  const layout = {
    margin: { l: 55, r: 10, t: 10, b: 40 }, height: 220,
    xaxis: { title: { text: f.tool === "profile" ? `distance (${f.lateral_unit})` : f.unit } },
    yaxis: { title: { text: f.tool === "profile" ? f.unit : "pixels" } },
  };
  await window.Plotly.react(chart, [trace], layout, { displaylogo: false, responsive: true });
}

function showPlaneMap(name, f) {
  const figure = $("measure-plane");
  figure.hidden = f.tool !== "plane";
  if (figure.hidden) return;
  const url = `/api/results/${encodeURIComponent(name)}/measure/plane.png?${query()}`;
  fetch(url).then(async (r) => {
    if (!r.ok) return;
    const [low, high] = (r.headers.get("X-Range") || "0,0").split(",").map(Number);
    $("measure-plane-map").src = URL.createObjectURL(await r.blob());
    $("measure-plane-caption").textContent = `height above the plane: ${fmt(low, 2)} .. ${fmt(high, 2)} ${f.unit} (turbo, symmetric)`;
  });
}

export async function measure() {
  const name = resultName();
  const status = $("measure-hint");
  if (!name) { status.textContent = "no result shown yet"; return; }
  const chosen = tool();
  if (!corners() && !TOOLS[chosen].whole) { status.textContent = TOOLS[chosen].hint; return; }
  const base = `/api/results/${encodeURIComponent(name)}/measure/${chosen}`;
  const extra = chosen === "histogram" ? { bins: $("measure-bins").value || "64" } : {};
  status.textContent = "measuring ...";
  try {
    const figures = await request("GET", `${base}?${query(extra)}`); // a refusal shows in the hint
    showFigures(figures);
    $("measure-csv").href = `${base}?${query({ ...extra, format: "csv" })}`;
    $("measure-csv").download = `${name}-${chosen}.csv`;
    $("measure-csv").hidden = false;
    status.textContent = `${chosen} on ${name}` + (corners() ? ` at ${corners().join(", ")}` : " (whole map)");
    showPlaneMap(name, figures);
    await drawChart(figures);
  } catch (e) {
    status.textContent = e.message;
    $("measure-figures").replaceChildren();
  }
  picks = [];
  drawOverlay();
  const table = $("measure-figures");
  table.dataset.count = String(Number(table.dataset.count || 0) + 1); // measurements finished (tests wait on it)
}

function reset() {
  picks = [];
  setCorners(null);
  $("measure-figures").replaceChildren();
  $("measure-csv").hidden = true;
  $("measure-plane").hidden = true;
  $("measure-chart").hidden = true;
  $("measure-hint").textContent = TOOLS[tool()].hint;
  $("measure-bins-label").hidden = tool() !== "histogram";
  $("measure-whole").hidden = !TOOLS[tool()].whole;
  drawOverlay();
}

export function bindMeasure() {
  $("measure-panel").replaceChildren($("measure-template").content.cloneNode(true));
  overlay = document.createElement("canvas");
  overlay.className = "measure-overlay";
  overlay.dataset.testid = "measure-overlay";
  $("height-map").parentElement.appendChild(overlay);
  $("height-map").addEventListener("click", pick);
  $("measure-tool").onchange = reset;
  $("measure-run").onclick = () => measure();
  $("measure-whole").onclick = () => { picks = []; setCorners(null); measure(); };
  FIELDS.forEach((f) => { $("measure-" + f).onchange = drawOverlay; });
  // a new result on screen: what was measured belonged to the old one
  new MutationObserver(reset).observe($("view-result"), { attributeFilter: ["data-result"] });
  window.addEventListener("resize", drawOverlay);
  reset();
}
