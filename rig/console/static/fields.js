// Input errors as sentences next to the field they are about. A value the page cannot send (an
// empty or non-numeric field) is explained here without asking the server; a value the server
// refuses shows the server's one line under the field, and a refused camera setting goes back to
// what the camera really has.
import { $, request } from "./api.js";

// The error line under ``input``'s label (made on first use); empty text clears it.
export function fieldError(input, text) {
  const label = input.closest("label") || input;
  let line = label.nextElementSibling;
  if (!line || !line.classList.contains("field-error")) {
    line = document.createElement("div");
    line.className = "field-error";
    line.dataset.testid = input.id + "-error";
    label.after(line);
  }
  line.textContent = text || "";
  line.hidden = !text;
  input.classList.toggle("invalid", Boolean(text));
}

// A number typed into ``input``, or null with the reason shown next to it.
export function numberIn(input, what) {
  const text = input.value.trim();
  if (text === "") { fieldError(input, `Enter ${what}.`); return null; }
  const value = Number(text);
  if (!Number.isFinite(value)) { fieldError(input, `"${text}" is not a number; enter ${what}.`); return null; }
  return value;
}

// A comma-separated list of numbers, or null with the first bad entry named next to the field.
export function numbersIn(input, what) {
  const parts = input.value.split(",").map((p) => p.trim());
  if (parts.every((p) => p === "")) { fieldError(input, `Enter ${what}.`); return null; }
  for (const [i, part] of parts.entries()) {
    if (part === "" || !Number.isFinite(Number(part))) {
      fieldError(input, `Entry ${i + 1} ("${part}") is not a number; enter ${what}.`);
      return null;
    }
  }
  return parts.map(Number);
}

// A camera setting (exposure, gain): checked here, sent, and on a refusal the field shows the
// reason and the value the camera keeps.
export async function sendCameraSetting(input, key, what) {
  const value = numberIn(input, what);
  if (value !== null) {
    try {
      await request("PUT", "/api/exposure", { [key]: value });
      fieldError(input, "");
      return;
    } catch (e) { fieldError(input, e.message); }
  }
  const actual = await request("GET", "/api/exposure").catch(() => null);
  if (actual && actual[key] !== null && actual[key] !== undefined) input.value = String(actual[key]);
}

// The server's refusal of a form, under the field its first word names (``heights_mm: ...``);
// under ``fallback`` when it names none.
export function showRefusal(message, fieldsByKey, fallback) {
  for (const input of Object.values(fieldsByKey)) fieldError(input, "");
  const key = Object.keys(fieldsByKey).find((k) => message.startsWith(k + ":") || message.startsWith(k + "."));
  fieldError(key ? fieldsByKey[key] : fallback, message);
}

export function clearErrors(...inputs) { for (const input of inputs) fieldError(input, ""); }
