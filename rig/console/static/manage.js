// Managing captures, results and calibrations from the page: delete (to the data directory's
// trash, with Undo), rename, restore from the trash, and a change in another tab followed here.
// The lists of the Captures view get their Rename and Delete buttons from here (they are drawn by
// captures.js); the server announces every change as a "data" message to every page.
import { $, api } from "./api.js";
import { loadCaptures } from "./captures.js";

const listeners = new Set(); // modules that redraw on a change (the calibrations panel)
let lastDeleted = null;

export function onDataChange(redraw) { listeners.add(redraw); }

function notice(text, undo) {
  const bar = $("notice");
  bar.querySelector("span").textContent = text;
  $("notice-undo").hidden = !undo;
  bar.hidden = false;
}

export async function deleteEntry(kind, name) {
  const reply = await api("DELETE", `/api/${kind}/${encodeURIComponent(name)}`).catch(() => null);
  if (!reply) return;
  lastDeleted = reply;
  notice(`${kind}/${name} moved to the trash of the data directory`, true);
}

export async function renameEntry(kind, name, to) {
  const target = to ?? prompt(`New name for ${kind}/${name}`, name);
  if (!target || target === name) return;
  const reply = await api("POST", `/api/${kind}/${encodeURIComponent(name)}/rename`, { to: target }).catch(() => null);
  const kept = reply?.results_naming_old || [];
  if (reply) notice(`${kind}/${name} renamed to ${reply.name}` + (kept.length ? `; ${kept.join(", ")} still name ${name} in their report` : ""), false);
}

async function restore(kind, entry) {
  const reply = await api("POST", "/api/trash/restore", { kind, entry }).catch(() => null);
  if (reply) notice(`${kind}/${reply.name} restored`, false);
  return reply;
}

async function undo() {
  if (!lastDeleted) return;
  const { kind, entry } = lastDeleted;
  lastDeleted = null;
  await restore(kind, entry);
}

async function drawTrash() {
  const list = $("trash-list");
  if (!list) return;
  const reply = await api("GET", "/api/trash").catch(() => null);
  if (!reply) return;
  list.replaceChildren(...reply.entries.map((e) => {
    const li = document.createElement("li");
    li.textContent = `${e.kind}/${e.name} (deleted ${e.trashed_utc}) `;
    li.dataset.entry = e.entry;
    li.append(button("Restore", "restore", () => restore(e.kind, e.entry)));
    return li;
  }));
  $("trash-count").textContent = String(reply.entries.length);
}

export function button(text, testid, action) {
  const b = document.createElement("button");
  b.textContent = text; b.dataset.testid = testid; b.className = "small";
  b.onclick = (event) => { event.stopPropagation(); action(); };
  return b;
}

// Rename and Delete on each complete capture and each result of the Captures view.
function decorate(list, kind) {
  for (const li of list.querySelectorAll("li:not(.managed):not(.incomplete)")) {
    const name = li.dataset.name || li.textContent;
    li.dataset.name = name;
    li.classList.add("managed");
    li.append(" ", button("Rename", "rename", () => renameEntry(kind, name)), " ", button("Delete", "delete", () => deleteEntry(kind, name)));
  }
}

export function dataChanged(message) {
  if ($("view-captures").classList.contains("active")) loadCaptures().catch(() => {});
  drawTrash();
  for (const redraw of listeners) redraw(message);
  const shown = $("view-result").dataset.result;
  if (message.kind === "results" && shown && shown === (message.old || message.name) && message.change !== "restored") {
    $("result-title").textContent = `${shown}: ${message.change === "renamed" ? "renamed to " + message.name : "deleted (in the trash)"}`;
  }
}

export function bindManage() {
  $("notice-undo").onclick = undo;
  $("notice-close").onclick = () => { $("notice").hidden = true; };
  const observe = (id, kind) => new MutationObserver(() => decorate($(id), kind)).observe($(id), { childList: true });
  observe("capture-list", "captures");
  observe("capture-results", "results");
  document.addEventListener("view", (event) => { if (event.detail === "captures") drawTrash(); });
}
