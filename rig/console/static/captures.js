// The Captures view: captures and their results, reprocessing with other options, comparing two results.
import { $, api, fillSelect } from "./api.js";
import { openResult } from "./result.js";

let selected = null;
let reprocessJob = null;

export async function loadCaptures() {
  const [captures, results] = await Promise.all([api("GET", "/api/captures"), api("GET", "/api/results")]);
  const list = $("capture-list");
  list.replaceChildren();
  for (const c of captures.captures) {
    const li = document.createElement("li");
    li.textContent = c.error ? `${c.name} (${c.error})` : `${c.name} — ${c.scene}, ${c.width}x${c.height}, ${c.frames} frames`;
    li.dataset.name = c.name;
    if (c.error) interruptedButtons(li, c.name);
    else li.onclick = () => openCapture(c.name);
    li.classList.toggle("selected", selected === c.name);
    list.appendChild(li);
  }
  const names = results.results.map((r) => r.name);
  fillSelect($("compare-a"), names, $("compare-a").value || names[0] || "");
  fillSelect($("compare-b"), names, $("compare-b").value || names[1] || names[0] || "");
  if (selected && !captures.captures.some((c) => c.name === selected)) selected = null; // renamed or deleted
  if (selected) await openCapture(selected);
}

// An interrupted scan: process what it holds, or move it to the data directory's trash.
function interruptedButtons(li, name) {
  li.classList.add("incomplete");
  const salvage = document.createElement("button");
  salvage.textContent = "Salvage"; salvage.dataset.testid = "salvage";
  salvage.onclick = async () => {
    const options = { correction: $("opt-correction").value };
    const reply = await api("POST", `/api/captures/${encodeURIComponent(name)}/salvage`, { options }).catch(() => null);
    if (reply) { reprocessJob = reply.job.id; $("reprocess-note").textContent = `salvaging into ${reply.job.name}`; }
  };
  const discard = document.createElement("button");
  discard.textContent = "Discard"; discard.dataset.testid = "discard";
  discard.onclick = async () => {
    if (!confirm(`Move ${name} to the trash folder of the data directory?`)) return;
    const reply = await api("POST", `/api/captures/${encodeURIComponent(name)}/discard`, {}).catch(() => null);
    if (reply) { $("reprocess-note").textContent = `${name} moved to ${reply.moved_to}`; loadCaptures().catch(() => {}); }
  };
  li.append(" ", salvage, " ", discard);
}

async function openCapture(name) {
  selected = name;
  document.querySelectorAll("#capture-list li").forEach((li) => li.classList.toggle("selected", li.dataset.name === name));
  const info = await api("GET", `/api/captures/${encodeURIComponent(name)}`);
  $("capture-title").textContent = name;
  const m = info.manifest;
  $("capture-info").textContent = `scene ${m.scene}, created ${m.created_utc}\n${m.camera.width}x${m.camera.height}, ${m.patterns.length} patterns, complete: ${m.complete}`;
  $("reprocess").disabled = reprocessJob !== null;
  const list = $("capture-results");
  list.replaceChildren();
  for (const r of info.results) {
    const li = document.createElement("li");
    li.textContent = r;
    li.onclick = () => openResult(r, { focus: true });
    list.appendChild(li);
  }
}

async function reprocess() {
  if (!selected) return;
  const options = { unwrap: $("opt-unwrap").value, denoise: $("opt-denoise").value, correction: $("opt-correction").value };
  try {
    const reply = await api("POST", "/api/process", { capture: selected, options });
    reprocessJob = reply.job.id;
    $("reprocess").disabled = true;
    $("reprocess-note").textContent = `processing ${reply.job.name}`;
  } catch (e) { $("reprocess-note").textContent = e.message; }
}

// Processing progress and the end of a reprocessing job this page started; any finished job
// refreshes the lists (another tab's reprocessing too).
export function captureProgress(message) {
  if (message.job !== reprocessJob) return;
  const e = message.event;
  if (e.total) { $("reprocess-progress").max = e.total; $("reprocess-progress").value = e.done; }
  $("reprocess-note").textContent = `${e.task}: ${e.note} (${e.done} of ${e.total})`;
}

export function captureJob(job) {
  if (job.state === "running") return;
  if (job.id === reprocessJob) {
    reprocessJob = null;
    $("reprocess-note").textContent = `${job.name} ${job.state}` + (job.error ? `: ${job.error}` : "");
  }
  if ($("view-captures").classList.contains("active")) loadCaptures().catch(() => {});
}

async function compare() {
  const a = $("compare-a").value, b = $("compare-b").value;
  if (!a || !b) return;
  const query = `a=${encodeURIComponent(a)}&b=${encodeURIComponent(b)}`;
  const figures = await api("GET", `/api/compare?${query}`).catch(() => null);
  if (!figures) return;
  const stamp = Date.now();
  $("compare-img-a").src = `/api/results/${encodeURIComponent(a)}/map.png?v=${stamp}`;
  $("compare-img-b").src = `/api/results/${encodeURIComponent(b)}/map.png?v=${stamp}`;
  $("compare-diff").src = `/api/compare.png?${query}&v=${stamp}`;
  $("compare-cap-a").textContent = a;
  $("compare-cap-b").textContent = b;
  $("compare-cap-diff").textContent = `${a} − ${b}`;
  $("compare-high").textContent = `+${figures.scale[1].toPrecision(3)} ${figures.unit}`;
  $("compare-low").textContent = `${figures.scale[0].toPrecision(3)} ${figures.unit}`;
  $("compare-figures").textContent = figures.rms === undefined ? "no pixel valid in both"
    : `rms ${figures.rms.toFixed(3)} ${figures.unit}, max |d| ${figures.max_abs.toFixed(3)} ${figures.unit}, mean ${figures.mean.toFixed(3)} ${figures.unit}`;
}

// The option lists come from the server (GET /api/options: the processing registries), never
// from this page; each choice's one-line description is its tooltip.
export async function loadOptions() {
  const options = await api("GET", "/api/options");
  const fill = (select, option) => {
    fillSelect(select, option.choices.map((c) => c.name), option.default);
    for (const [i, choice] of option.choices.entries()) select.options[i].title = choice.description;
    select.dataset.default = option.default;
  };
  fill($("opt-unwrap"), options.unwrap);
  fill($("opt-denoise"), options.denoise);
  for (const select of document.querySelectorAll("select.correction")) fill(select, options.correction);
}

export function bindCaptures() {
  $("reprocess").onclick = reprocess;
  $("compare-button").onclick = compare;
  document.addEventListener("view", (event) => { if (event.detail === "captures") loadCaptures().catch(() => {}); });
}
