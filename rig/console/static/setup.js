// The scan setup (part, notes, patterns, frequencies, steps, exposures; the server remembers it per
// data folder and checks every value), the exposure assistant's suggestion, the first-run hint, and
// the Result view's exposure map. The server decides; this module shows and sends.
import { $, api, fillSelect, showView } from "./api.js";

let suggestion = null;

const list = (text) => text.split(/[,\s]+/).filter(Boolean).map(Number);
const text = (values) => (values || []).join(", ");

function fill(id, value) {
  if (document.activeElement !== $(id)) $(id).value = value;
}

export function showSetup(status) {
  const setup = status.scan_setup;
  if (!setup) return;
  fill("setup-part", setup.part);
  fill("setup-notes", setup.notes);
  fillSelect($("setup-pattern-set"), setup.pattern_sets, setup.pattern_set);
  fill("setup-frequencies", text(setup.frequencies));
  $("setup-frequencies").placeholder = text(setup.used.frequencies);
  fill("setup-steps", setup.steps ?? "");
  $("setup-steps").placeholder = String(setup.used.steps);
  fill("setup-exposures", text(setup.exposures_us));
  $("setup-frames").textContent = `${setup.used.frames} frames per scan` + (setup.note ? ` — ${setup.note}` : "");
  $("first-run").hidden = status.calibrations.length > 0;
  $("hdr-auto").disabled = status.busy;
}

async function send(changes) {
  $("setup-error").textContent = "";
  try {
    await api("PUT", "/api/scan-setup", changes);
  } catch (e) {
    $("setup-error").textContent = e.message;  // next to the fields; the field keeps what was typed
  }
}

function numbers(id, key) {
  const raw = $(id).value.trim();
  const values = list(raw);
  if (values.some((v) => Number.isNaN(v))) {
    $("setup-error").textContent = `${key}: expected numbers separated by commas, found "${raw}"`;
    return;
  }
  send({ [key]: values });
}

async function hdrAuto() {
  $("hdr-suggestion").textContent = "pre-capture at two exposures ...";
  $("hdr-use").hidden = true;
  try {
    suggestion = await api("POST", "/api/scan-setup/hdr-auto", {});
    $("hdr-suggestion").textContent = suggestion.lines.join("\n");
    $("hdr-suggestion").dataset.coverage = String(suggestion.coverage);
    $("hdr-use").hidden = false;
  } catch (e) {
    $("hdr-suggestion").textContent = e.message;
  }
}

export function bindSetup() {
  $("setup-part").onchange = () => send({ part: $("setup-part").value });
  $("setup-notes").onchange = () => send({ notes: $("setup-notes").value });
  $("setup-pattern-set").onchange = () => send({ pattern_set: $("setup-pattern-set").value });
  $("setup-frequencies").onchange = () => numbers("setup-frequencies", "frequencies");
  $("setup-steps").onchange = () => {
    const raw = $("setup-steps").value.trim();
    send({ steps: raw === "" ? null : Number(raw) });
  };
  $("setup-exposures").onchange = () => numbers("setup-exposures", "exposures_us");
  $("hdr-auto").onclick = hdrAuto;
  $("hdr-use").onclick = () => { if (suggestion) send({ exposures_us: suggestion.exposures_us }); };
  $("first-run-calibrate").onclick = () => showView("calibration");
}

// The Result view's exposure map: shown for a capture at several exposures only.
export function showExposureMap(name, summary) {
  const entries = summary.exposures || [];
  $("exposure-panel").hidden = entries.length === 0;
  if (!entries.length) return;
  $("exposure-map").src = `/api/results/${encodeURIComponent(name)}/exposure.png?v=${Date.now()}`;
  $("exposure-legend").replaceChildren(...entries.map((e) => {
    const item = document.createElement("li");
    const swatch = document.createElement("span");
    swatch.className = "swatch";
    swatch.style.background = e.colour;
    item.append(swatch, `${e.exposure_us} µs: ${(100 * e.share).toFixed(1)} %`);
    return item;
  }));
}
