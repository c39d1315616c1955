// drive-gateway status page. Every string from the gateway is put in the page as text
// (textContent, attribute values), never parsed as HTML.
"use strict";

const S = {
  drives: new Map(),      // id -> row (the state's JSON)
  trends: new Map(),      // id -> {t: [], speed: [], ref: [], current: [], unit}
  events: [],
  commands: false,
  offset: 0,              // server clock - browser clock, s
  span: 600,
  pageId: (crypto.randomUUID ? crypto.randomUUID() : String(Math.random()).slice(2)).slice(0, 36),
  client: "",  // this page's label in control_client, from its first accepted command
  user: null,   // the logged-in user (GET /api/session), with their role and CSRF token
  role: null,
  csrf: null,
  sessionKnown: false,
  dirty: new Set(),
};
const MAX_EVENTS = 100;
const COLUMNS = [
  ["id", "drive"], ["device", "device"], ["where", "bus / address"], ["comm", "comm"],
  ["status", "status"], ["speed", "speed rpm"], ["ref", "reference rpm"],
  ["current", "current"], ["fault", "fault"], ["control", "in control"], ["age", "last change"],
];

// ---------------------------------------------------------------- DOM helpers

function el(tag, props, text) {
  const node = document.createElement(tag);
  if (props) {
    for (const [k, v] of Object.entries(props)) {
      if (k === "class") node.className = v;
      else if (k.startsWith("data-")) node.setAttribute(k, String(v));
      else node[k] = v;
    }
  }
  if (text !== undefined && text !== null) node.textContent = String(text);
  return node;
}
function $(id) { return document.getElementById(id); }
function num(v, digits) { return v === null || v === undefined ? "–" : Number(v).toFixed(digits); }
function serverNow() { return Date.now() / 1000 + S.offset; }
function ageText(ts) {
  if (!ts) return "–";
  const age = Math.max(0, serverNow() - ts);
  if (age < 60) return age.toFixed(1) + " s";
  if (age < 3600) return (age / 60).toFixed(1) + " min";
  return (age / 3600).toFixed(1) + " h";
}
function badge(value) { return el("span", {class: "badge", "data-v": value}, value); }

// ---------------------------------------------------------------- drives table

function rowFor(id) {
  let tr = document.querySelector(`#drives-body tr[data-drive="${CSS.escape(id)}"]`);
  if (!tr) {
    tr = el("tr", {"data-drive": id});
    for (const [key] of COLUMNS) tr.appendChild(el("td", {"data-col": key}));
    if (S.commands) tr.appendChild(el("td", {"data-col": "commands"}));
    $("drives-body").appendChild(tr);
  }
  return tr;
}

function cell(tr, key) { return tr.querySelector(`td[data-col="${key}"]`); }

function renderDrive(d) {
  const tr = rowFor(d.id);
  tr.dataset.comm = d.comm;
  tr.dataset.status = d.status;
  cell(tr, "id").textContent = d.id;
  cell(tr, "device").textContent = d.device;
  cell(tr, "where").textContent = `${d.bus} / ${d.address}`;
  cell(tr, "comm").replaceChildren(badge(d.comm));
  cell(tr, "status").replaceChildren(badge(d.status), ...safetyBadges(d));
  const speed = cell(tr, "speed"); speed.className = "num"; speed.textContent = num(d.speed_rpm, 1);
  const ref = cell(tr, "ref"); ref.className = "num"; ref.textContent = num(d.speed_ref_rpm, 1);
  const current = cell(tr, "current"); current.className = "num";
  current.textContent = d.current_a !== null && d.current_a !== undefined
    ? num(d.current_a, 2) + " A"
    : (d.current_pct_flc !== null && d.current_pct_flc !== undefined ? num(d.current_pct_flc, 0) + " %FLC" : "–");
  const fault = cell(tr, "fault"); fault.className = "fault";
  fault.textContent = faultText(d);
  const control = cell(tr, "control");
  control.textContent = d.control_source === "none"
    ? "–" : `${d.control_source}${d.control_client ? " " + d.control_client : ""}`;
  control.title = control.textContent;
  cell(tr, "age").dataset.ts = d.ts;
  cell(tr, "age").textContent = ageText(d.ts);
  if (S.commands) renderCommands(tr, d);
}

// The codes as the device's documents write them (0x8130 for a CANopen EMCY code).
function faultText(d) {
  if (d.fault_code === null || d.fault_code === undefined) {
    return d.alarm ? `alarm ${d.alarm_code_text ?? d.alarm_code ?? ""}`.trimEnd() : "";
  }
  return `${d.fault_code_text ?? d.fault_code}${d.fault_text ? ": " + d.fault_text : ""}`;
}

// Issue 32: what limits the gateway's command of a drive, said beside its status.
function safetyBadges(d) {
  const out = [];
  const add = (cls, text, title) => {
    const b = badge(cls); b.textContent = text; b.title = title; b.dataset.safety = cls;
    out.push(b);
  };
  if (d.local_control) add("local", "local", "the drive ignores the network's run commands");
  if (d.failsafe === false) {
    add("no-failsafe", "no fail-safe", "keeps running if the gateway is lost: " + (d.failsafe_text || ""));
  }
  if (d.doubtful) add("doubtful", "doubtful", "frames that contradict each other were heard");
  return out;
}

function renderAges() {
  for (const td of document.querySelectorAll('#drives-body td[data-col="age"]')) {
    td.textContent = ageText(Number(td.dataset.ts));
  }
}

function renderHead() {
  const head = $("drives-head");
  head.replaceChildren(...COLUMNS.map(([key, title]) => el("th", {"data-col": key}, title)));
  if (S.commands) head.appendChild(el("th", null, "command"));
}

// ---------------------------------------------------------------- commands (web.commands)

function renderCommandBar() {
  const bar = $("command-bar");
  if (!S.commands) {
    // no commands: the bar only for a login the gateway asks for (web.anonymous = "none")
    bar.hidden = !S.sessionKnown || S.role !== null || S.user !== null;
    if (bar.hidden) bar.replaceChildren();
    else if (!$("login")) { bar.replaceChildren(el("span", {id: "login"})); renderLogin(); }
    return;
  }
  bar.hidden = false;
  if ($("token")) return;
  const token = el("input", {type: "password", id: "token", placeholder: "token", autocomplete: "off"});
  token.value = sessionStorage.getItem("drive-gateway-token") || "";
  token.addEventListener("change", () => sessionStorage.setItem("drive-gateway-token", token.value));
  bar.replaceChildren(el("span", {id: "login"}),
    el("label", {htmlFor: "token"}, "Commands are on: token "), token,
    el("span", {id: "command-result"}));
  renderLogin();
}

// ---------------------------------------------------------------- login (gateway/web/auth.py)

async function loadSession() {
  try {
    const s = await (await fetch("/api/session")).json();
    S.user = s.user; S.role = s.role; S.csrf = s.csrf || null; S.sessionKnown = true;
  } catch (e) { /* the page stays as it is */ }
  renderCommandBar();
  renderLogin();
}

function renderLogin() {
  const box = $("login");
  if (!box) return;
  if (S.user) {
    const out = el("button", {type: "button", id: "logout"}, "log out");
    out.addEventListener("click", logout);
    box.replaceChildren(el("span", {id: "who"}, `${S.user} (${S.role})`), out);
    return;
  }
  const user = el("input", {id: "login-user", placeholder: "user", autocomplete: "username"});
  const pass = el("input", {type: "password", id: "login-password", placeholder: "password",
    autocomplete: "current-password"});
  const go = el("button", {type: "button", id: "login-button"}, "log in");
  go.addEventListener("click", () => login(user.value, pass.value));
  pass.addEventListener("keydown", (e) => { if (e.key === "Enter") login(user.value, pass.value); });
  box.replaceChildren(user, pass, go, el("span", {id: "login-result"}));
}

async function login(user, password) {
  const r = await fetch("/api/login", {
    method: "POST", headers: {"Content-Type": "application/json"},
    body: JSON.stringify({user, password}),
  });
  const answer = await r.json();
  if (r.ok) {
    S.user = answer.user; S.role = answer.role; S.csrf = answer.csrf;
    renderLogin();
    if (!S.commands) location.reload();  // the page the login opens (web.anonymous = "none")
  } else {
    const result = $("login-result");
    if (result) result.textContent = ` ${answer.error}`;
  }
}

async function logout() {
  await fetch("/api/logout", {method: "POST", headers: {"X-CSRF-Token": S.csrf || ""}});
  S.user = null; S.csrf = null;
  renderLogin();
}

function renderCommands(tr, d) {
  const td = cell(tr, "commands");
  if (td.childElementCount) return;
  const box = el("div", {class: "commands"});
  const speed = el("input", {type: "number", step: "any", placeholder: "rpm", "data-role": "speed"});
  const buttons = [
    ["run", {run: true}], ["stop", {run: false}], ["reset", {fault_reset: true}],
  ].map(([label, body]) => {
    const b = el("button", {type: "button", "data-cmd": label}, label);
    b.addEventListener("click", () => command(d.id, body));
    return b;
  });
  const set = el("button", {type: "button", "data-cmd": "speed"}, "set");
  set.addEventListener("click", () => {
    if (speed.value !== "") command(d.id, {speed_rpm: Number(speed.value)});
  });
  box.append(...buttons, speed, set);
  td.appendChild(box);
}

async function command(id, body) {
  const result = $("command-result");
  const token = ($("token") || {}).value || "";
  const headers = {"Content-Type": "application/json", "X-Page-Id": S.pageId};
  if (S.csrf) headers["X-CSRF-Token"] = S.csrf;  // a logged-in session
  if (token || !S.csrf) headers["Authorization"] = "Bearer " + token;
  try {
    const r = await fetch(`/api/drives/${encodeURIComponent(id)}/command`, {
      method: "POST",
      headers,
      body: JSON.stringify(body),
    });
    const answer = await r.json();
    if (answer.client) S.client = answer.client;  // this page's published label
    if (result && Object.keys(body).length) {
      result.textContent = answer.accepted ? ` ${id}: accepted` : ` ${id}: refused: ${answer.error}`;
    }
  } catch (e) {
    if (result) result.textContent = ` ${id}: ${e}`;
  }
}

function keepAlive() {
  // The command watchdog (command_timeout) is fed by the client in control: this page.
  if (!S.commands) return;
  for (const d of S.drives.values()) {
    if (d.control_source === "web" && S.client && d.control_client === S.client) {
      command(d.id, {});
    }
  }
}

// ---------------------------------------------------------------- buses

function renderBuses(buses) {
  const box = $("buses");
  box.replaceChildren(...buses.map((b) => {
    const div = el("div", {class: "bus", "data-bus": b.name});
    div.appendChild(el("h3", null, `${b.name} (${b.adapter})`));
    const stations = el("div", {class: "stations"});
    for (const s of b.stations) {
      const parts = [`${s.address} ${s.drive}`, s.station_state || s.comm];
      if (s.response_last_ms !== undefined) parts.push(`${num(s.response_last_ms, 2)} ms`);
      if (s.retries) parts.push(`${s.retries} retries`);
      if (s.timeouts) parts.push(`${s.timeouts} timeouts`);
      stations.appendChild(el("span", {class: "station", "data-comm": s.comm, "data-drive": s.drive}, parts.join(" · ")));
    }
    div.appendChild(stations);
    const f = b.figures;
    const figs = el("div", {class: "figures"});
    const items = [
      ["cycle", f.cycle_last_ms, 2, " ms"], ["median", f.cycle_median_ms, 2, " ms"],
      ["avg", f.cycle_avg_ms, 2, " ms"], ["max", f.cycle_max_ms, 1, " ms"],
      ["cycles", f.cycles, 0, ""], ["retries", f.retries, 0, ""], ["timeouts", f.timeouts, 0, ""],
      ["restarts", b.restarts, 0, ""],
    ];
    for (const [name, v, digits, unit] of items) {
      if (v !== undefined && v !== null) figs.appendChild(el("span", {"data-fig": name}, `${name} ${num(v, digits)}${unit}`));
    }
    for (const [kind, v] of Object.entries(b.errors)) {
      if (v) figs.appendChild(el("span", {"data-fig": kind}, `${kind} ${v}`));
    }
    div.appendChild(figs);
    const details = el("details");
    details.appendChild(el("summary", null, "all figures"));
    details.appendChild(el("div", null, Object.entries(b.details).map(([k, v]) => `${k}: ${v}`).join(" · ")));
    div.appendChild(details);
    return div;
  }));
}

// ---------------------------------------------------------------- events and health

function eventItem(e) {
  const li = el("li", {"data-kind": e.kind, "data-drive": e.drive});
  li.append(el("time", null, new Date(e.ts * 1000).toLocaleTimeString()),
    el("span", {class: "kind"}, e.kind), el("span", null, `${e.drive}: ${e.text}`));
  return li;
}

function addEvents(events, replace) {
  if (replace) S.events = [];
  S.events.push(...events);
  S.events = S.events.slice(-MAX_EVENTS);
  $("events").replaceChildren(...S.events.slice().reverse().map(eventItem));
}

// The header's counts, from the drives' own states (gateway/web/page.py says the same in
// the first HTML): a faulted drive is online but not ok.
function summaryText() {
  const c = {drives: 0, ok: 0, faulted: 0, offline: 0};
  for (const d of S.drives.values()) {
    c.drives++;
    if (d.comm !== "online") c.offline++;
    else if (d.status === "faulted" || d.status === "tripped") c.faulted++;
    else c.ok++;
  }
  return `${c.drives} drives: ${c.ok} ok, ${c.faulted} faulted, ${c.offline} offline`;
}

function renderSummary() {
  const up = S.startedAt === undefined ? "" : ` · up ${ageText(S.startedAt)}`;
  $("summary").textContent = summaryText() + up;
}

function renderHealth(h) {
  if (!h || !h.name) return;
  S.startedAt = serverNow() - h.uptime_s;
  renderSummary();
  const rows = [["name", h.name], ["version", h.version], ["uptime", `${num(h.uptime_s, 0)} s`],
    ["drives", h.drives], ["online", h.online], ["of them faulted", h.faulted]];
  for (const [bus, b] of Object.entries(h.buses || {})) {
    rows.push([`bus ${bus}`, `${b.adapter}, live: ${(b.live || []).join(", ") || "none"}, restarts ${b.restarts}`]);
  }
  $("health").replaceChildren(...rows.flatMap(([k, v]) => [el("dt", null, k), el("dd", null, v)]));
}

// ---------------------------------------------------------------- trends

function trendFor(id) {
  let t = S.trends.get(id);
  if (!t) { t = {t: [], speed: [], ref: [], current: [], unit: "A"}; S.trends.set(id, t); }
  return t;
}

function addPoint(id, p) {
  const t = trendFor(id);
  const last = t.t.length ? t.t[t.t.length - 1] : -Infinity;
  if (p[0] <= last) return;
  t.t.push(p[0]); t.speed.push(p[1]); t.ref.push(p[2]); t.current.push(p[3]);
  S.dirty.add(id);
}

function setHistory(id, h) {
  const t = trendFor(id);
  const later = [];
  const lastT = h.t.length ? h.t[h.t.length - 1] : -Infinity;
  for (let i = 0; i < t.t.length; i++) if (t.t[i] > lastT) later.push([t.t[i], t.speed[i], t.ref[i], t.current[i]]);
  t.t = h.t.slice(); t.speed = h.speed.slice(); t.ref = h.ref.slice(); t.current = h.current.slice();
  t.unit = h.current_unit;
  for (const p of later) addPoint(id, p);
  S.dirty.add(id);
}

function trim(t) {
  const oldest = serverNow() - S.span;
  let n = 0;
  while (n < t.t.length && t.t[n] < oldest) n++;
  if (n) for (const k of ["t", "speed", "ref", "current"]) t[k].splice(0, n);
}

function trendBox(id) {
  let box = document.querySelector(`#trends .trend[data-drive="${CSS.escape(id)}"]`);
  if (!box) {
    box = el("div", {class: "trend", "data-drive": id});
    box.append(el("h3", null, id), el("canvas"), el("div", {class: "legend"}));
    $("trends").appendChild(box);
  }
  return box;
}

function extent(arrays) {
  let lo = 0, hi = 0;
  for (const a of arrays) for (const v of a) if (v !== null) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  if (hi - lo < 1e-9) hi = lo + 1;
  return [lo, hi];
}

function drawLine(ctx, xs, ys, x, y, color) {
  ctx.strokeStyle = color; ctx.lineWidth = 1.5 * devicePixelRatio; ctx.beginPath();
  let pen = false;
  for (let i = 0; i < xs.length; i++) {
    if (ys[i] === null) { pen = false; continue; }
    if (pen) ctx.lineTo(x(xs[i]), y(ys[i])); else ctx.moveTo(x(xs[i]), y(ys[i]));
    pen = true;
  }
  ctx.stroke();
}

function drawTrend(id) {
  const t = trendFor(id);
  trim(t);
  const box = trendBox(id);
  const canvas = box.querySelector("canvas");
  const w = Math.max(1, Math.round(canvas.clientWidth * devicePixelRatio));
  const h = Math.max(1, Math.round(canvas.clientHeight * devicePixelRatio));
  if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
  const ctx = canvas.getContext("2d");
  ctx.clearRect(0, 0, w, h);
  const css = getComputedStyle(document.documentElement);
  const pad = 4 * devicePixelRatio;
  const end = serverNow(), start = end - S.span;
  const x = (v) => pad + (v - start) / S.span * (w - 2 * pad);
  const [slo, shi] = extent([t.speed, t.ref]);
  const [clo, chi] = extent([t.current]);
  const ys = (v) => h - pad - (v - slo) / (shi - slo) * (h - 2 * pad);
  const yc = (v) => h - pad - (v - clo) / (chi - clo) * (h - 2 * pad);
  ctx.strokeStyle = css.getPropertyValue("--line"); ctx.lineWidth = 1;
  ctx.beginPath(); ctx.moveTo(pad, ys(0)); ctx.lineTo(w - pad, ys(0)); ctx.stroke();
  drawLine(ctx, t.t, t.ref, x, ys, css.getPropertyValue("--ref").trim());
  drawLine(ctx, t.t, t.speed, x, ys, css.getPropertyValue("--speed").trim());
  drawLine(ctx, t.t, t.current, x, yc, css.getPropertyValue("--current").trim());
  const n = t.t.length - 1;
  box.dataset.points = String(t.t.length);
  box.dataset.lastT = n >= 0 ? String(t.t[n]) : "";
  box.dataset.lastRef = n >= 0 && t.ref[n] !== null ? String(t.ref[n]) : "";
  box.dataset.lastSpeed = n >= 0 && t.speed[n] !== null ? String(t.speed[n]) : "";
  const legend = box.querySelector(".legend");
  legend.replaceChildren(
    el("span", {class: "speed"}, `speed ${n >= 0 ? num(t.speed[n], 0) : "–"} rpm`),
    el("span", {class: "ref"}, `reference ${n >= 0 ? num(t.ref[n], 0) : "–"} rpm`),
    el("span", {class: "current"}, `current ${n >= 0 ? num(t.current[n], 1) : "–"} ${t.unit === "%FLC" ? "%FLC" : "A"}`),
    el("span", null, `scale ${num(slo, 0)}…${num(shi, 0)} rpm, ${num(clo, 1)}…${num(chi, 1)}`),
  );
}

function drawTrends() {
  for (const id of S.dirty) drawTrend(id);
  S.dirty.clear();
}

async function loadHistory() {
  if (S.range) { loadRange(); return; }
  try {
    const r = await fetch("/api/history");
    const h = await r.json();
    S.span = h.span;
    $("trend-span").textContent = `last ${Math.round(h.span / 60)} min, a sample every ${h.period} s`;
    for (const [id, hist] of Object.entries(h.drives)) setHistory(id, hist);
    requestAnimationFrame(drawTrends);
  } catch (e) { /* the next snapshot asks again */ }
}

// The trend over a longer range (the select beside the heading): the gateway's history,
// averaged per bucket (/api/drives/<id>/history); the live points are added as they come.
S.range = 0;  // s chosen beyond the 10-minute ring; 0: the ring

function column(h, name) { return (h.values && h.values[name]) || h.t.map(() => null); }

async function loadRange() {
  const range = S.range;
  const step = Math.max(1, Math.round(range / 600));
  S.span = range;
  for (const id of S.drives.keys()) {
    try {
      const r = await fetch(`/api/drives/${encodeURIComponent(id)}/history?start=now-${range}&step=${step}`);
      if (!r.ok || S.range !== range) continue;
      const h = await r.json();
      const amps = Boolean(h.values.current_a);
      setHistory(id, {
        t: h.t, speed: column(h, "speed_rpm"), ref: column(h, "speed_ref_rpm"),
        current: column(h, amps ? "current_a" : "current_pct_flc"),
        current_unit: amps || !h.values.current_pct_flc ? trendFor(id).unit : "%FLC",
      });
    } catch (e) { /* the next refresh asks again */ }
  }
  $("trend-span").textContent = `averages per ${step} s from the gateway's history`;
  requestAnimationFrame(drawTrends);
}

function chooseRange() {
  S.range = Number($("trend-range").value) || 0;
  for (const t of S.trends.values()) for (const k of ["t", "speed", "ref", "current"]) t[k] = [];
  loadHistory();
}

// ---------------------------------------------------------------- the feed

function onSnapshot(m) {
  S.commands = Boolean(m.gateway.commands);
  $("gw-name").textContent = m.gateway.name;
  $("gw-version").textContent = m.gateway.version;
  document.title = `${m.gateway.name}: drive-gateway`;
  S.span = m.trend.span;
  renderHead();
  renderCommandBar();
  $("drives-body").replaceChildren();
  $("drives-body").dataset.rendered = "feed";  // the server's first rows replaced
  S.drives.clear();
  for (const d of m.drives) {
    S.drives.set(d.id, d); renderDrive(d);
    trendFor(d.id).unit = d.current_unit; trendBox(d.id);
  }
  addEvents(m.events, true);
  renderBuses(m.buses);
  renderHealth(m.health);
  renderSummary();
  loadHistory();
}

function onUpdate(m) {
  for (const d of m.drives || []) { S.drives.set(d.id, d); renderDrive(d); trendFor(d.id).unit = d.current_unit; }
  if (m.drives && m.drives.length) renderSummary();
  for (const [id, p] of Object.entries(m.points || {})) addPoint(id, p);
  if (m.events) addEvents(m.events, false);
  if (m.buses) renderBuses(m.buses);
  if (m.health) renderHealth(m.health);
  if (S.dirty.size) requestAnimationFrame(drawTrends);
}

let retry = 500;
function connect() {
  const link = $("link");
  const scheme = location.protocol === "https:" ? "wss:" : "ws:";
  const ws = new WebSocket(`${scheme}//${location.host}/ws`);
  ws.onopen = () => { link.dataset.state = "live"; link.textContent = "live"; retry = 500; };
  ws.onmessage = (ev) => {
    const m = JSON.parse(ev.data);
    S.offset = m.now - Date.now() / 1000;
    if (m.type === "snapshot") onSnapshot(m); else onUpdate(m);
  };
  ws.onclose = () => {
    link.dataset.state = "lost"; link.textContent = "connection lost: retrying";
    setTimeout(connect, retry);
    retry = Math.min(retry * 2, 8000);
  };
}

loadSession();
connect();
$("trend-range").addEventListener("change", chooseRange);
setInterval(() => { if (S.range) loadRange(); }, 60000);
setInterval(renderAges, 1000);
setInterval(keepAlive, 1000);
setInterval(() => { for (const id of S.trends.keys()) S.dirty.add(id); requestAnimationFrame(drawTrends); }, 5000);
