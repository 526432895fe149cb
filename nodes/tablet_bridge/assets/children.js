// The therapist page's children: the list of the codes the robot knows (from its stored
// sessions, as the bridge reads them: sessions played, the last date), a search, a new code
// (checked by the bridge with the rules of a user id; nothing is stored until a session of it
// starts), the child chosen for the next session, and that child's progress (the report's
// body, made by the bridge from the stored sessions) with a print button. therapist.js calls
// childrenRequest() after a login and when a session ends, and passes the bridge's
// `children`, `child_checked` and `progress` messages to the functions below.
"use strict";

let knownChildren = [];   // {user_id, sessions, last_ms} as the bridge read them
let addedCodes = [];      // codes added on this page, not stored yet
let chosenChild = null;

function childrenRequest() {
  if (socket && typeof pin === "string" && pin) socket.send({ type: "children", pin: pin });
}

function formatDay(ms) {
  return new Date(ms).toLocaleDateString(document.documentElement.lang, {
    year: "numeric", month: "short", day: "numeric",
  });
}

function childMeta(c) {
  if (!c.sessions) return t("not_played_yet");
  const n = c.sessions === 1 ? t("one_session") : t("n_sessions").replace("{n}", c.sessions);
  return c.last_ms ? n + " · " + t("last_on").replace("{date}", formatDay(c.last_ms)) : n;
}

function renderChildren() {
  const query = $("child-search").value.trim().toLowerCase();
  const stored = new Set(knownChildren.map((c) => c.user_id));
  const all = addedCodes
    .filter((code) => !stored.has(code))
    .map((code) => ({ user_id: code, sessions: 0, last_ms: null }))
    .concat(knownChildren);
  const shown = all.filter((c) => c.user_id.toLowerCase().includes(query));
  const list = $("children");
  list.replaceChildren(...shown.map((c) => {
    const li = document.createElement("li");
    const b = document.createElement("button");
    b.type = "button";
    b.className = "child";
    b.dataset.user = c.user_id;
    b.setAttribute("aria-pressed", String(c.user_id === chosenChild));
    const code = document.createElement("span");
    code.className = "code";
    code.textContent = c.user_id;
    const meta = document.createElement("span");
    meta.className = "meta";
    meta.textContent = childMeta(c);
    b.append(code, meta);
    b.addEventListener("click", () => chooseChild(c.user_id));
    li.appendChild(b);
    return li;
  }));
  const empty = $("children-empty");
  empty.classList.toggle("hidden", shown.length > 0);
  empty.textContent = all.length ? t("no_match") : t("no_children");
  $("chosen-code").textContent = chosenChild || "–";
  updateButtons();
}

function chooseChild(code) {
  chosenChild = code;
  renderChildren();
}

function showChildren(m) {
  knownChildren = m.children;
  renderChildren();
}

function childChecked(m) {
  if (!addedCodes.includes(m.user_id)) addedCodes.unshift(m.user_id);
  $("new-code").value = "";
  $("child-search").value = "";
  chooseChild(m.user_id);
}

function showProgress(m) {
  const box = $("progress");
  // The bridge's report body: every value from a file is escaped there.
  box.innerHTML = m.html;
  box.dataset.user = m.user_id;
  show("progress");
  $("progress-back").focus();
}

function openProgress() {
  if (!chosenChild || !pin) return;
  $("progress").replaceChildren();
  $("progress").textContent = t("loading");
  socket.send({ type: "progress", pin: pin, user_id: chosenChild });
}

$("child-search").addEventListener("input", renderChildren);
$("new-child").addEventListener("submit", (event) => {
  event.preventDefault();
  const code = $("new-code").value;
  if (pin) socket.send({ type: "new_child", pin: pin, user_id: code });
});
$("show-progress").addEventListener("click", openProgress);
$("progress-back").addEventListener("click", () => show("main"));
$("progress-print").addEventListener("click", () => window.print());
renderChildren();
