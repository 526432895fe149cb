// The therapist tablet: unlock with the PIN, then watch the game (state, engagement trend,
// each decision with its Q-values, each result) and command it; proposals are proposal.js's,
// the children (choosing one, their progress) children.js's. The bridge checks everything
// again; the buttons' enabled state is only a hint. The game's rules (which phases are a
// sequence under way, the actions and feedback by name, a sequence's score and the session's
// total) come from the bridge; this page only shows and translates them.
"use strict";
const $ = (id) => document.getElementById(id);
const TREND_SECONDS = 300;

let pin = null;        // kept in memory only, so a reconnect can log in again
let loggedIn = false;
let phase = "unknown";
let running = false;
let engagement = [];   // {t, smoothed, mean, has_faces}

// "login", "main" (the session) or "progress" (a child's progress, printable).
function show(view) {
  $("login-view").classList.toggle("hidden", view !== "login");
  $("topbar").classList.toggle("hidden", view === "login");
  $("columns").classList.toggle("hidden", view !== "main");
  $("progress-view").classList.toggle("hidden", view !== "progress");
  document.body.dataset.view = view;
}

function toast(text, bad) {
  const el = $("toast");
  el.textContent = text;
  el.className = bad ? "bad" : "good";
}

function command(kind, extra) {
  if (!pin) return;
  if (!socket.send(Object.assign({ type: "command", pin: pin, command: kind }, extra || {}))) {
    toast(t("offline"), true);
  }
}

function updateButtons() {
  const chosen = typeof chosenChild === "string" && chosenChild !== "";
  $("start").disabled = running || phase === "paused" || !chosen;
  $("show-progress").disabled = !chosen;
  $("pause").disabled = !running;
  $("resume").disabled = phase !== "paused";
  $("stop").disabled = !(running || phase === "paused");
  for (const l of [1, 2, 3]) $("override-" + l).disabled = !(running || phase === "paused");
}

function fmt(x, digits) {
  return typeof x === "number" && isFinite(x) ? x.toFixed(digits) : "–";
}

const ENDED = ["finished", "stopped", "emergency_stopped"];

function showGame(g) {
  // A session that just ended is stored now: the list shows it.
  if (ENDED.includes(g.phase) && !ENDED.includes(phase) && phase !== "unknown") childrenRequest();
  phase = g.phase;
  running = g.running;
  const badge = $("phase");
  badge.textContent = t("phase_" + g.phase);
  badge.dataset.phase = g.phase;
  $("session-label").textContent = g.session_id ? t("session") + " " + g.session_id : "";
  $("g-sequence").textContent = g.sequence_index + " / " + (g.sequences_planned || "–");
  $("g-level").textContent = g.level || "–";
  $("g-feedback").textContent = g.sequence_index ? t(g.feedback_name) : "–";
  $("g-score").textContent = g.last_score;
  $("g-fallback").textContent = g.policy_fallback ? t("yes") : t("no");
  $("g-user").textContent = g.user_id
    ? g.user_id + " (" + (g.cluster < 0 ? t("default_cluster") : "cluster " + g.cluster) + ")"
    : "–";
  $("g-status").textContent = g.status || "–";
  // The disk of the session files and the bag is low or full (the game manager says how).
  $("disk-warning").classList.toggle("hidden", !g.disk_warning);
  $("disk-detail").textContent = g.disk_warning || "";
  updateButtons();
  proposalFollowsGame(g);
}

function cell(row, content, className) {
  const td = document.createElement("td");
  if (content instanceof Node) td.appendChild(content); else td.textContent = content;
  if (className) td.className = className;
  row.appendChild(td);
  return td;
}

function qValues(d) {
  // One column per action: its Q-value as a bar (scaled within this decision) and its softmax
  // probability; the chosen action is outlined, masked actions are faded.
  const box = document.createElement("div");
  box.className = "qvalues";
  const finite = d.q_values.filter((q) => typeof q === "number");
  const lo = Math.min(0, ...finite), hi = Math.max(0, ...finite);

  d.q_values.forEach((q, i) => {
    const item = document.createElement("div");
    item.className = "q" + (i === d.action ? " chosen" : "") +
      ((d.probabilities[i] || 0) === 0 ? " masked" : "");
    const bar = document.createElement("div");
    bar.className = "bar";
    bar.style.height = (hi > lo && typeof q === "number" ? 100 * (q - lo) / (hi - lo) : 0) + "%";
    const name = document.createElement("b");
    name.textContent = t(d.action_names[i] + "_short");
    const value = document.createElement("span");
    value.textContent = fmt(q, 2);
    const p = document.createElement("small");
    p.textContent = "p " + fmt(d.probabilities[i], 2);
    item.append(bar, name, value, p);
    item.title = t(d.action_names[i]);
    box.appendChild(item);
  });
  return box;
}

function addDecision(d) {
  const body = $("decisions").tBodies[0];
  if (body.rows.length && body.rows[0].dataset.session !== d.session_id) body.replaceChildren();
  const row = document.createElement("tr");
  row.dataset.session = d.session_id;
  cell(row, d.step);
  cell(row, "(" + d.state.join(", ") + ")");
  const chosen = document.createElement("div");
  chosen.textContent = t(d.action_names[d.action]) + " → L" + d.level + ", " + t(d.feedback_name);
  const mode = document.createElement("small");
  mode.className = d.explored ? "explored" : "greedy";
  mode.textContent = (d.explored ? t("explored") : t("greedy")) + " · T " + fmt(d.temperature, 2);
  const action = document.createElement("div");
  action.append(chosen, mode);
  cell(row, action);
  cell(row, qValues(d));
  row.title = d.model_used;
  body.prepend(row);
}

function faces(list) {
  const span = document.createElement("span");
  span.className = "faces";
  for (const e of list) {
    const img = document.createElement("img");
    img.src = "/assets/faces/" + e + ".svg";
    img.alt = img.title = t(e);
    span.appendChild(img);
  }
  return span;
}

function addResult(r) {
  const body = $("results").tBodies[0];
  if (body.rows.length && body.rows[0].dataset.session !== r.session_id) body.replaceChildren();
  const row = document.createElement("tr");
  row.dataset.session = r.session_id;
  const outcome = r.timed_out ? "timeout" : r.outcome === 1 ? "right" : "wrong";
  row.className = "result " + outcome;
  row.dataset.score = r.score;
  cell(row, r.sequence_index);
  cell(row, r.level + (r.overridden ? " *" : ""));
  // What the robot said above what the child tapped, face under face.
  const pair = document.createElement("div");
  pair.className = "pair";
  pair.append(faces(r.sequence), faces(r.answer));
  cell(row, pair);
  cell(row, t(outcome), "outcome");
  cell(row, fmt(r.engagement, 2));
  cell(row, fmt(r.response_time, 1));
  body.prepend(row);
  // The session's score so far against the best its levels allow, as the bridge counts it.
  $("g-total").textContent = r.session_score + " / " + r.session_max_score;
}

function drawTrend() {
  const svg = $("chart");
  const ns = "http://www.w3.org/2000/svg";
  const W = 600, H = 200;
  const y = (v) => H / 2 - v * (H / 2 - 10);
  const el = (name, attrs) => {
    const e = document.createElementNS(ns, name);
    for (const k in attrs) e.setAttribute(k, attrs[k]);
    return e;
  };
  // The chart's text alternative (the svg is labelled by this title): what it shows now.
  const title = el("title", { id: "chart-label" });
  const last = engagement[engagement.length - 1];
  title.textContent = last
    ? t("chart_label").replace("{n}", engagement.length).replace("{e}", fmt(last.smoothed, 2))
    : t("chart_empty");
  svg.replaceChildren(
    title,
    el("line", { x1: 0, x2: W, y1: y(0), y2: y(0), class: "axis" }),
    el("line", { x1: 0, x2: W, y1: y(1), y2: y(1), class: "grid" }),
    el("line", { x1: 0, x2: W, y1: y(-1), y2: y(-1), class: "grid" }),
  );
  if (!engagement.length) return;
  // The window grows with the session, from one minute up to TREND_SECONDS.
  const end = engagement[engagement.length - 1].t;
  const span = Math.min(TREND_SECONDS, Math.max(60, end - engagement[0].t));
  const x = (tt) => W - (end - tt) / span * W;
  let path = "";
  let pen = false;
  for (const p of engagement) {
    if (end - p.t > span) continue;
    if (!p.has_faces) { pen = false; continue; }
    path += (pen ? " L" : " M") + x(p.t).toFixed(1) + " " + y(p.smoothed).toFixed(1);
    pen = true;
    svg.appendChild(el("circle", { cx: x(p.t).toFixed(1), cy: y(p.mean).toFixed(1), r: 2, class: "mean" }));
  }
  svg.appendChild(el("path", { d: path, class: "smoothed" }));
}

function addEngagement(p) {
  engagement.push(p);
  const end = p.t;
  engagement = engagement.filter((q) => end - q.t <= TREND_SECONDS);
}

function onMessage(m) {
  switch (m.type) {
    case "login_required":
      loggedIn = false;
      if (pin) socket.send({ type: "login", pin: pin }); else show("login");
      break;
    case "logged_in":
      loggedIn = true;
      $("login-error").textContent = "";
      // The bridge sends everything it holds after a login: a page logging in again (it
      // reconnected, or the bridge was restarted) starts its tables afresh, not twice over.
      $("decisions").tBodies[0].replaceChildren();
      $("results").tBodies[0].replaceChildren();
      $("g-total").textContent = "–";
      clearProposal();
      show(document.body.dataset.view === "progress" ? "progress" : "main");
      childrenRequest();
      break;
    case "game": showGame(m); break;
    case "decision": addDecision(m); break;
    case "result": addResult(m); break;
    case "proposal": showProposal(m); break;
    case "engagement": addEngagement(m); drawTrend(); break;
    case "engagement_history": engagement = m.points; drawTrend(); break;
    case "children": showChildren(m); break;
    case "child_checked": childChecked(m); break;
    case "progress": showProgress(m); break;
    case "command_sent":
      toast(t("sent") + ": " + m.command + " (" + m.session_id + ", #" + m.command_id + ")", false);
      break;
    case "accepted": toast(t("sent") + ": " + m.what, false); break;
    case "rejected":
      if (!loggedIn) {
        pin = null;
        show("login");
        $("login-error").textContent = t("rejected") + ": " + m.reason;
      } else {
        toast(t("rejected") + ": " + m.reason, true);
      }
      break;
  }
}

$("login-form").addEventListener("submit", (event) => {
  event.preventDefault();
  pin = $("pin").value;
  $("pin").value = "";
  socket.send({ type: "login", pin: pin });
});
$("start").addEventListener("click", () => {
  // The cluster only when chosen under "Advanced": otherwise the policy's default plays.
  const cluster = parseInt($("cluster").value, 10);
  const extra = { user_id: chosenChild };
  if (!isNaN(cluster)) extra.cluster = cluster;
  command("start", extra);
});
$("pause").addEventListener("click", () => command("pause"));
$("resume").addEventListener("click", () => command("resume"));
$("stop").addEventListener("click", () => command("stop"));
$("estop").addEventListener("click", () => command("emergency_stop"));
for (const l of [1, 2, 3]) {
  $("override-" + l).addEventListener("click", () => command("override_level", { level: l }));
}

translatePage();
drawTrend();
// The PIN and the child's results cross the network readable by anyone on it: only over
// plain HTTP to another computer (the bridge serves that only with allow_plain_http).
const host = location.hostname;
const loopback = host === "localhost" || host.startsWith("127.") || host === "[::1]";
const unencrypted = location.protocol !== "https:" && !loopback;
$("unencrypted").classList.toggle("hidden", !unencrypted);
document.body.classList.toggle("unencrypted", unencrypted);
// Connected once every script of the page has run (children.js's functions handle messages).
let socket = null;
document.addEventListener("DOMContentLoaded", () => {
  socket = connectSocket("/ws/therapist", onMessage, (online) => {
    $("offline").classList.toggle("hidden", online);
    if (!online) loggedIn = false;
  });
});
