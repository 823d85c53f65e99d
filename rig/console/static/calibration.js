// The Calibration view: the wizard (from the page's <template id="calibration-template">), its
// prompts (a real rig asks the operator to move the plane), steps, progress and result.
import { $, api, request } from "./api.js";
import { clearErrors, numberIn, numbersIn, showRefusal } from "./fields.js";

function finishSteps(className) {
  document.querySelectorAll("#cal-steps li.current").forEach((li) => { li.className = className; });
}

export function showPrompt(prompt) {
  if (prompt) $("cal-prompt").querySelector("span").textContent = prompt.text;
  $("cal-prompt").hidden = !prompt;
}

export function calibrationProgress(message) {
  const e = message.event;
  if (e.total) { $("cal-progress").max = e.total; $("cal-progress").value = e.done; }
  if (e.kind === "message") {
    document.querySelectorAll("#cal-steps li").forEach((li) => { li.className = "done"; });
    const li = document.createElement("li"); li.textContent = e.note; li.className = "current";
    $("cal-steps").appendChild(li);
  }
}

export function calibrationResult(m) {
  finishSteps("done");
  const figure = (label, value, unit) => (value === null || value === undefined ? "" : `${label} = ${Number(value).toPrecision(7)} ${unit}`);
  $("cal-result").textContent = `${m.name}: ${m.model}\n` + [figure("l0", m.l0_mm, "mm"), figure("d0", m.d0_mm, "mm"),
    figure("f0", m.f0_per_mm, "/mm")].filter(Boolean).join(", ") + "\n" + m.lines.join("\n");
  $("cal-result").dataset.done = "true";
}

export function calibrationJob(job) {
  if (job.kind !== "calibrate") return;
  $("cal-start").disabled = job.state === "running";
  if (job.state === "failed" || job.state === "cancelled") {
    finishSteps("failed");
    showPrompt(null);
    $("cal-result").textContent = `${job.name} ${job.state}: ${job.error}`;
  }
}

async function start() {
  const fields = { name: $("cal-name"), heights_mm: $("cal-heights"), board_views: $("cal-views"), model: $("cal-model"), gamma_levels: $("cal-gamma") };
  clearErrors(...Object.values(fields));
  // the calibration plan's own checks name the command's options
  Object.assign(fields, { "--heights": fields.heights_mm, "--model": fields.model, "--gamma": fields.gamma_levels });
  const heights = numbersIn($("cal-heights"), "the plane heights in mm above the reference plane, separated by commas (e.g. 25, 50, 100)");
  const views = numberIn($("cal-views"), "how many tilted board views to take (0 for none)");
  const gamma = numberIn($("cal-gamma"), "the number of gamma ramp levels (0 for none)");
  if (heights === null || views === null || gamma === null) return;
  $("cal-steps").replaceChildren();
  $("cal-result").textContent = "";
  delete $("cal-result").dataset.done;
  await request("POST", "/api/calibrate", {
    name: $("cal-name").value || null, heights_mm: heights, board_views: views,
    model: $("cal-model").value, gamma_levels: gamma,
  }).catch((e) => showRefusal(e.message, fields, $("cal-start")));
}

export function buildWizard() {
  $("calibration-wizard").replaceChildren($("calibration-template").content.cloneNode(true));
  $("cal-start").onclick = start;
  $("cal-done").onclick = async () => { $("cal-prompt").hidden = true; await api("POST", "/api/calibrate/answer", {}).catch(() => {}); };
}
