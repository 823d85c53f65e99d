// Looking into the opened capture: any raw frame, and each phase-shifted group's wrapped phase
// and modulation (from the server: /api/captures/NAME/frames, .../groups/G/phase.png).
import { $, request } from "./api.js";

let listing = null;

async function open(name) {
  listing = null;
  $("look-what").replaceChildren();
  $("look-image").removeAttribute("src");
  const reply = await request("GET", `/api/captures/${encodeURIComponent(name)}/frames`).catch(() => null);
  if (!reply || reply.capture !== currentCapture()) return;
  listing = reply;
  const options = [];
  for (const g of reply.groups) {
    options.push([`groups/${g.group}/phase`, `wrapped phase: ${g.axis}, ${g.frequency} fringes, ${g.steps} steps`]);
    options.push([`groups/${g.group}/modulation`, `modulation: ${g.axis}, ${g.frequency} fringes`]);
  }
  for (const f of reply.frames.filter((f) => f.held)) options.push([`frames/${f.index}`, `frame ${f.index}: ${f.kind} (${f.what})`]);
  $("look-what").replaceChildren(...options.map(([value, label]) => {
    const o = document.createElement("option"); o.value = value; o.textContent = label; return o;
  }));
  show();
}

function currentCapture() {
  const title = $("capture-title").textContent;
  return title === "select a capture" ? null : title;
}

function show() {
  const name = currentCapture();
  const what = $("look-what").value;
  if (!name || !what) return;
  const url = `/api/captures/${encodeURIComponent(name)}/${what}.png`;
  fetch(url).then(async (r) => {
    if (!r.ok) { $("look-note").textContent = (await r.json().catch(() => ({}))).error || r.statusText; return; }
    const range = r.headers.get("X-Range");
    $("look-image").src = URL.createObjectURL(await r.blob());
    $("look-image").dataset.shows = what;
    $("look-note").textContent = range ? `colour scale ${range.split(",").map((v) => Number(v).toFixed(2)).join(" .. ")} ${r.headers.get("X-Unit")} (turbo)` : "raw frame, 8 bits";
  });
}

export function bindCaptureLook() {
  $("capture-look").replaceChildren($("capture-look-template").content.cloneNode(true));
  $("look-what").onchange = show;
  new MutationObserver(() => { const name = currentCapture(); if (name) open(name); })
    .observe($("capture-title"), { childList: true, characterData: true, subtree: true });
}
