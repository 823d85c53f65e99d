// fpp-rig console page: draws what the server sends and calls the JSON API. No rig logic here:
// every decision (what to scan, how to process, what is valid) is the server's, and every job runs
// on the server — a page that opens (or reloads) shows the running job and the newest result.
import { $, api, clientId, dropTokenFromAddress, showError, showView } from "./api.js";
import { bindCaptures, captureJob, captureProgress, loadOptions } from "./captures.js";
import { buildWizard, calibrationJob, calibrationProgress, calibrationResult, showPrompt } from "./calibration.js";
import { binaryMessage, bindSettings, showSettings } from "./live.js";
import { bindLive3d, live3dError, showLive3d } from "./live3d.js";
import { bindMeasure } from "./measure.js";
import { bindManage, dataChanged } from "./manage.js";
import { bindCalibrations, showCalibrations } from "./calibrations.js";
import { bindCaptureLook } from "./capturelook.js";
import { bindResult, openResult, resultSaved, showResult } from "./result.js";
import { bindSetup, showSetup } from "./setup.js";
import { buildVerify, showVerifyPrompt, verificationDone, verifyJob, verifyProgress } from "./verify.js";

const ownJobs = new Set(); // jobs this page started: only their results move it to the Result view
let lastFrameAt = null;
let scanClickedAt = null; // the page's own timings of its scans (benchmarks/bench_console.py reads them)

// One operator prompt at a time: a verification's shows in the Verify view, a calibration's in the wizard.
function showPrompts(prompt) {
  const verifying = Boolean(prompt) && String(prompt.job).startsWith("verify-");
  showPrompt(verifying ? null : prompt);
  showVerifyPrompt(verifying ? prompt : null);
}

function updateStatus(status) {
  $("state").textContent = status.state + (status.device_error ? " (device error)" : "");
  $("state").className = "state " + status.state;
  $("scan-button").disabled = status.busy;
  $("cal-start").disabled = status.busy;
  $("verify-start").disabled = status.busy;
  $("stop-button").disabled = !(status.busy || status.jobs.length);
  showSettings(status);
  showCalibrations(status.calibrations, status.calibration);
  showSetup(status);
  showLive3d(status);
  showPrompts(status.prompt);
}

// What a page that just opened shows: the running acquisition's progress and the newest result.
function catchUp(status) {
  for (const job of status.jobs) {
    if (job.kind === "calibrate") calibrationJob(job);
    else if (job.kind === "verify") verifyJob(job);
    else if (job.progress_kind === "scan") scanProgress({ job: job.id, event: { task: job.stage, kind: "step", done: job.done, total: job.total, note: "" } });
    else noteJob(job);
  }
  const latest = status.latest_result;
  if (latest && !$("view-result").dataset.result) {
    openResult(latest.name, {}, { final: latest.final, unlessNewer: true }).catch(() => {});
  }
}

function scanProgress(message) {
  const e = message.event;
  if (!e.total) return;
  $("scan-progress").max = e.total;
  $("scan-progress").value = e.done;
  $("scan-note").textContent = `${e.note || e.task} (${e.done} of ${e.total} frames)`;
  if (e.kind === "step" && e.done >= e.total && ownJobs.has(message.job) && lastFrameAt === null) {
    lastFrameAt = performance.now();
    if (scanClickedAt !== null) $("view-live").dataset.clickToLastFrameMs = String(lastFrameAt - scanClickedAt);
  }
}

function processProgress(message) {
  const e = message.event;
  if (e.total) { $("process-progress").max = e.total; $("process-progress").value = e.done; }
  $("process-note").textContent = `${e.task}: ${e.note} (stage ${e.done} of ${e.total})`;
  captureProgress(message);
}

function noteJob(job) {
  const text = { cancelled: `${job.kind} ${job.name} stopped: ${job.error}`, failed: `${job.kind} ${job.name} failed`,
    done: `${job.kind} ${job.name} done` }[job.state] || (job.stage === "processing" ? `processing ${job.name}` : null);
  if (text && job.kind !== "calibrate" && job.kind !== "verify") $("scan-note").textContent = text;
}

const handlers = {
  hello: (m) => { updateStatus(m.status); catchUp(m.status); },
  status: (m) => updateStatus(m.status),
  progress: (m) => ({ scan: scanProgress, process: processProgress, calibrate: calibrationProgress, verify: verifyProgress })[m.kind]?.(m),
  job: (m) => { noteJob(m.job); calibrationJob(m.job); captureJob(m.job); verifyJob(m.job); },
  result: (m) => {
    if (ownJobs.has(m.job) && m.since_last_frame_s !== null) $("view-result").dataset[m.final ? "serverFinalMs" : "serverQuickMs"] = String(1000 * m.since_last_frame_s);
    showResult(m.name, m.summary, m.final, { focus: ownJobs.has(m.job), lastFrameAt: ownJobs.has(m.job) ? lastFrameAt : null });
  },
  saved: (m) => resultSaved(m.name),
  error: (m) => showError(m.message),
  prompt: (m) => showPrompts(m),
  calibration: (m) => calibrationResult(m),
  verification: (m) => verificationDone(m).catch(() => {}),
  data: (m) => dataChanged(m),
  live3d: (m) => live3dError(m),
};

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  const socket = new WebSocket(`${scheme}://${location.host}/api/events?client=${clientId}`);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => socket.send(JSON.stringify({ live: true }));
  socket.onclose = () => { $("state").textContent = "disconnected"; setTimeout(connect, 1000); };
  socket.onmessage = (msg) => {
    if (typeof msg.data !== "string") { binaryMessage(msg.data); return; }
    const message = JSON.parse(msg.data);
    handlers[message.type]?.(message);
  };
}

async function scan() {
  $("scan-progress").value = 0;
  $("process-progress").value = 0;
  $("scan-note").textContent = "starting";
  lastFrameAt = null;
  scanClickedAt = performance.now();
  try {
    const reply = await api("POST", "/api/scan", { options: { correction: $("scan-correction").value } });
    ownJobs.add(reply.job.id);
  } catch (e) { $("scan-note").textContent = e.message; }
}

function bind() {
  document.querySelectorAll("nav button").forEach((button) => { button.onclick = () => showView(button.dataset.view); });
  $("error-close").onclick = () => { $("error").hidden = true; };
  $("scan-button").onclick = scan;
  $("stop-button").onclick = () => api("POST", "/api/stop", {}).catch(() => {});
  bindSettings();
  bindSetup();
  bindLive3d();
  bindResult();
  bindMeasure();
  bindManage();
  bindCalibrations();
  bindCaptureLook();
  bindCaptures();
  buildWizard();
  buildVerify();
}

dropTokenFromAddress();
bind();
loadOptions().catch(() => {});
connect();
