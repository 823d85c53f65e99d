// The Calibration view's list of calibrations: which one scans use (choose), rename, delete (to
// the trash, with Undo), and import an OpenCV FileStorage projector-camera calibration from a file.
// A refused import says why next to the field it concerns.
import { $, api, request } from "./api.js";
import { showCalibrationFigures } from "./calfigures.js";
import { button, deleteEntry, onDataChange, renameEntry } from "./manage.js";

async function draw() {
  const reply = await api("GET", "/api/calibrations").catch(() => null);
  if (reply) showCalibrations(reply.calibrations, reply.active);
}

// The list as the server has it (from GET /api/calibrations or any status message).
export function showCalibrations(calibrations, active) {
  const reply = { calibrations, active };
  const key = JSON.stringify(reply);
  const list = $("calibrations-list");
  if (!list || list.dataset.key === key) return;
  list.dataset.key = key;
  const rows = [{ name: "", label: "none (phase only)" }, ...reply.calibrations.map((name) => ({ name, label: name }))];
  list.replaceChildren(...rows.map(({ name, label }) => {
    const li = document.createElement("li");
    li.dataset.name = name;
    const active = (reply.active || "") === name;
    li.classList.toggle("selected", active);
    li.append(label + (active ? " — used by scans " : " "));
    if (!active) li.append(button("Use", "use", () => choose(name)));
    if (name) li.append(" ", button("Show", "show", () => showCalibrationFigures(name)),
      " ", button("Rename", "rename", () => renameEntry("calibrations", name)),
      " ", button("Delete", "delete", () => deleteEntry("calibrations", name)));
    return li;
  }));
  list.dataset.active = reply.active || "";
}

async function choose(name) {
  await api("PUT", "/api/calibration", { name: name || null }).catch(() => {});
  draw();
}

function fieldError(id, text) {
  const el = $(id);
  el.textContent = text || "";
  el.hidden = !text;
}

// Which field a refusal of the import is about: the name, the file, or the sizes.
function showImportError(message) {
  const aboutName = /^calibrations\/|name/.test(message) && !/\.(yml|yaml|xml|json)\b/.test(message);
  fieldError("import-name-error", aboutName ? message : "");
  fieldError("import-file-error", aboutName ? "" : message);
}

async function importFile() {
  fieldError("import-name-error", "");
  fieldError("import-file-error", "");
  const file = $("import-file").files[0];
  const name = $("import-name").value.trim();
  if (!file) { fieldError("import-file-error", "choose the OpenCV calibration file (.yml, .yaml or .xml)"); return; }
  if (!name) { fieldError("import-name-error", "give the calibration a name (letters, digits, '.', '_', '-')"); return; }
  const body = { name, file_name: file.name, text: await file.text(), pixel_centre: Number($("import-centre").value) };
  const reply = await request("POST", "/api/calibrations/import", body).catch((e) => { showImportError(e.message); return null; });
  if (!reply) return;
  $("import-note").textContent = `${reply.name} imported`;
  $("import-name").value = "";
  draw();
}

export function bindCalibrations() {
  $("calibrations-panel").replaceChildren($("calibrations-template").content.cloneNode(true));
  $("import-button").onclick = importFile;
  onDataChange((m) => { if (!m.kind || m.kind === "calibrations") draw(); });
  document.addEventListener("view", (event) => { if (event.detail === "calibration") draw(); });
  draw();
}
