// The console's API page: its OpenAPI document drawn as a list of routes with their parameters and
// body fields. Everything comes from /api/openapi.json on this server: it works offline.
const el = (tag, text, cls) => { const e = document.createElement(tag); if (text) e.textContent = text; if (cls) e.className = cls; return e; };

function resolve(schema, spec) {
  if (schema && schema.$ref) return resolve(spec.components.schemas[schema.$ref.split("/").pop()], spec);
  return schema || {};
}

function typeOf(schema, spec) {
  const s = resolve(schema, spec);
  if (s.anyOf) return s.anyOf.map((x) => typeOf(x, spec)).join(" | ");
  if (s.type === "array") return `array of ${typeOf(s.items, spec)}`;
  if (s.enum) return s.enum.map(String).join(" | ");
  return s.type || (s.title ? s.title : "object");
}

function table(rows, head) {
  const t = el("table");
  const h = t.createTHead().insertRow();
  for (const name of head) h.appendChild(el("th", name));
  for (const row of rows) { const r = t.insertRow(); for (const cell of row) r.insertCell().textContent = cell; }
  return t;
}

function route(path, method, op, spec) {
  const box = el("details", null, "route");
  box.dataset.route = `${method.toUpperCase()} ${path}`;
  const summary = el("summary");
  summary.append(el("span", method.toUpperCase(), "method " + method), path + "  ", el("span", op.summary || "", "note"));
  box.appendChild(summary);
  const body = el("div", null, "body");
  const params = (op.parameters || []).map((p) => [p.name, p.in, typeOf(p.schema, spec), p.required ? "yes" : "", p.description || p.schema?.description || ""]);
  if (params.length) body.append(el("h4", "parameters"), table(params, ["name", "in", "type", "required", "description"]));
  const json = op.requestBody?.content?.["application/json"]?.schema;
  if (json) {
    const s = resolve(json, spec);
    const fields = Object.entries(s.properties || {}).map(([name, f]) => [name, typeOf(f, spec), (s.required || []).includes(name) ? "yes" : "", f.description || ""]);
    body.append(el("h4", "JSON body (unknown fields are refused)"), table(fields, ["field", "type", "required", "description"]));
  }
  body.append(el("p", "answers: " + Object.keys(op.responses || {}).join(", ") + "; a refusal is {\"error\": \"one line\"}", "note"));
  box.appendChild(body);
  return box;
}

async function draw() {
  const spec = await (await fetch("/api/openapi.json")).json();
  document.title = `${spec.info.title} API ${spec.info.version}`;
  const byTag = new Map();
  for (const [path, ops] of Object.entries(spec.paths)) {
    for (const [method, op] of Object.entries(ops)) {
      const tag = (op.tags || ["other"])[0];
      if (!byTag.has(tag)) byTag.set(tag, []);
      byTag.get(tag).push(route(path, method, op, spec));
    }
  }
  const out = document.getElementById("api-routes");
  for (const [tag, routes] of byTag) out.append(el("h2", tag, "tag"), ...routes);
  out.dataset.routes = String([...byTag.values()].reduce((n, r) => n + r.length, 0));
}

draw();
