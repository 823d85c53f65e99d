// Calls to the console's JSON API, and the one place errors are shown.
// Every request says which page sent it (X-Console-Client): the server refuses a request that
// changes something without a JSON body or that header (no cross-site form can forge it).

export const clientId = crypto.randomUUID ? crypto.randomUUID() : String(Math.random()).slice(2);
export const $ = (id) => document.getElementById(id);

export async function api(method, path, body) {
  try { return await request(method, path, body); } catch (e) { showError(e.message); throw e; }
}

// The same request without the page's error banner: for a refusal shown next to its field.
export async function request(method, path, body) {
  const options = { method, headers: { "X-Console-Client": clientId } };
  if (body !== undefined) {
    options.headers["Content-Type"] = "application/json";
    options.body = JSON.stringify(body);
  }
  const response = await fetch(path, options);
  const text = await response.text();
  let data = null;
  try { data = text ? JSON.parse(text) : null; } catch (e) { data = { error: text }; }
  if (!response.ok) throw new Error((data && data.error) || response.statusText);
  return data;
}

export function showError(message) {
  $("error-text").textContent = message;
  $("error").hidden = false;
}

export function fillSelect(select, values, chosen, label) {
  const key = values.join("\n");
  if (select.dataset.key !== key) {
    select.replaceChildren(...values.map((v) => {
      const option = document.createElement("option");
      option.value = v; option.textContent = label ? label(v) : v;
      return option;
    }));
    select.dataset.key = key;
  }
  if (document.activeElement !== select && chosen !== undefined) select.value = chosen;
}

// The access token came in the address (?token=...): the server has set it as a cookie with this
// page, so it leaves the address bar (and the history, and what the operator copies).
export function dropTokenFromAddress() {
  const url = new URL(location.href);
  if (!url.searchParams.has("token")) return;
  url.searchParams.delete("token");
  history.replaceState(null, "", url.pathname + url.search + url.hash);
}

// Views: only the operator's own clicks and jobs move this tab to another view.
export function showView(name) {
  document.querySelectorAll("nav button").forEach((b) => b.classList.toggle("active", b.dataset.view === name));
  document.querySelectorAll(".view").forEach((v) => v.classList.toggle("active", v.id === "view-" + name));
  document.dispatchEvent(new CustomEvent("view", { detail: name }));
}
