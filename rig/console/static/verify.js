// The Verify view: the guided session of `rig verify` (a job on the server; a real rig's prompts are
// answered with Done), its report (PASS/FAIL, PF, PS, SD, F against their MPE, the per-position
// table, the report's figures) and the verification history of the calibration, plotted over time.
import { $, api, fillSelect } from "./api.js";

const QUANTITIES = ["PF", "PS", "SD", "F"];
const NAMES = { PF: "probing error form", PS: "probing error size", SD: "sphere-spacing error", F: "flatness error" };
const SIGNED = new Set(["PS", "SD"]); // signed: measured minus calibrated
const mm = (v, signed) => (v === null || v === undefined ? "-" : (signed && v >= 0 ? "+" : "") + Number(v).toFixed(3));

export function showVerifyPrompt(prompt) {
  const box = $("verify-prompt");
  if (!box) return;
  if (prompt) box.querySelector("span").textContent = prompt.text;
  box.hidden = !prompt;
}

export function verifyProgress(message) {
  const e = message.event;
  if (e.total) { $("verify-progress").max = e.total; $("verify-progress").value = e.done; }
  $("verify-note").textContent = e.kind === "message" ? e.note : `${e.task} (${e.done} of ${e.total})`;
}

export function verifyJob(job) {
  if (job.kind !== "verify") return;
  $("verify-start").disabled = job.state === "running";
  if (job.state === "failed" || job.state === "cancelled") {
    showVerifyPrompt(null);
    $("verify-note").textContent = `${job.name} ${job.state}: ${job.error}`;
  }
}

export async function verificationDone(message) {
  $("verify-note").textContent = message.summary;
  await openVerification(message.name);
  await loadHistory(message.calibration);
}

function quantityTable(report) {
  const table = $("verify-quantities");
  table.replaceChildren();
  const head = table.insertRow();
  for (const h of ["", "quantity", "worst (mm)", "MPE (mm)", ""]) head.appendChild(document.createElement("th")).textContent = h;
  for (const q of QUANTITIES) {
    const entry = report[q];
    const row = table.insertRow();
    row.dataset.quantity = q;
    row.className = entry.pass ? "pass" : "fault";
    for (const text of [q, NAMES[q], mm(entry.worst_mm, SIGNED.has(q)), mm(entry.mpe_mm), entry.pass ? "pass" : "FAIL"]) row.insertCell().textContent = text;
  }
}

function positionTable(report) {
  const table = $("verify-positions");
  table.replaceChildren();
  const head = table.insertRow();
  for (const h of ["position", "where", "quantity", "value (mm)", ""]) head.appendChild(document.createElement("th")).textContent = h;
  for (const q of QUANTITIES) {
    for (const p of report[q].positions) {
      const row = table.insertRow();
      row.className = p.pass ? "" : "fault";
      for (const text of [p.position, p.where, q, p.value_mm === null ? (p.why || "not found") : mm(p.value_mm, SIGNED.has(q)), p.pass ? "" : "FAIL"]) row.insertCell().textContent = text;
    }
  }
}

function figures(name, names) {
  $("verify-figures").replaceChildren(...names.filter((f) => f !== "history.png").map((f) => {
    const figure = document.createElement("figure");
    const img = figure.appendChild(document.createElement("img"));
    img.src = `/api/verifications/${encodeURIComponent(name)}/figures/${encodeURIComponent(f)}`;
    img.alt = f; img.dataset.testid = "verify-figure";
    figure.appendChild(document.createElement("figcaption")).textContent = f.replace(".png", "");
    return figure;
  }));
}

export async function openVerification(name) {
  const { report, figures: names } = await api("GET", `/api/verifications/${encodeURIComponent(name)}`);
  const verdict = $("verify-verdict");
  verdict.textContent = `${name}: ${report.pass ? "PASS" : "FAIL"}`;
  verdict.className = "verdict " + (report.pass ? "pass" : "fail");
  verdict.dataset.verdict = report.pass ? "PASS" : "FAIL";
  $("verify-report").textContent = [report.summary, ...report.failures, ...report.drift.warnings, ...report.notes].join("\n");
  quantityTable(report);
  positionTable(report);
  figures(name, names);
  verdict.dataset.name = name;
}

export async function loadHistory(calibration) {
  if (!calibration) return;
  const history = await api("GET", `/api/calibrations/${encodeURIComponent(calibration)}/verifications`);
  const plot = $("verify-history");
  plot.dataset.runs = String(history.entries.length);
  if (!window.Plotly) return;
  const traces = QUANTITIES.map((q) => ({
    name: q, mode: "lines+markers", type: "scatter",
    x: history.series[q].map((p) => p.created), y: history.series[q].map((p) => p.worst_mm),
  }));
  const layout = { title: { text: `verifications of ${calibration}: worst value of each quantity (mm)` }, margin: { l: 50, r: 10, t: 40, b: 40 },
    yaxis: { title: { text: "mm" } }, height: 360 };
  await window.Plotly.react(plot, traces, layout, { responsive: true, displaylogo: false });
}

async function start() {
  $("verify-note").textContent = "starting";
  const mpe = $("verify-mpe").value.split(",").map(Number);
  await api("POST", "/api/verify", {
    name: $("verify-name").value || null, calibration: $("verify-calibration").value || null,
    spheres: Number($("verify-spheres").value), ball_bars: Number($("verify-bars").value), planes: Number($("verify-planes").value),
    mpe_mm: Object.fromEntries(QUANTITIES.map((q, i) => [q, mpe[i]])),
  }).catch(() => {});
}

export async function loadVerifyChoices() {
  const { calibrations, active } = await api("GET", "/api/calibrations");
  fillSelect($("verify-calibration"), calibrations, active || calibrations[0]);
  await loadHistory($("verify-calibration").value);
}

export function buildVerify() {
  $("verify-panel").replaceChildren($("verify-template").content.cloneNode(true));
  $("verify-start").onclick = start;
  $("verify-done").onclick = async () => { $("verify-prompt").hidden = true; await api("POST", "/api/verify/answer", {}).catch(() => {}); };
  $("verify-calibration").onchange = () => loadHistory($("verify-calibration").value).catch(() => {});
  document.addEventListener("view", (event) => { if (event.detail === "verify") loadVerifyChoices().catch(() => {}); });
}
