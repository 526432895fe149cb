// The child tablet: shows the four faces, collects one tapped sequence per task from the
// bridge and submits it. It shows no right/wrong: the robot gives the feedback.
"use strict";
const ui = {
  prompt: document.getElementById("prompt"),
  slots: document.getElementById("slots"),
  faces: [...document.querySelectorAll(".face")],
  undo: document.getElementById("undo"),
  done: document.getElementById("done"),
  offline: document.getElementById("offline"),
  note: document.getElementById("note"),
};
let task = null;      // the task on screen: {sequence_id, length, choices, timeout}
let taps = [];
let shownAt = 0;
let mode = "waiting"; // waiting | answering | sending | sent
let phase = "idle";

function render() {
  const paused = phase === "paused";
  const answering = mode === "answering" && !paused;
  document.body.className = "child " + (paused ? "paused" : mode);
  // Which task is on screen, for whoever checks the page (the browser test).
  document.body.dataset.sequence = task ? String(task.sequence_id) : "";
  let prompt = "listen";
  if (paused) prompt = "paused";
  else if (mode === "answering") prompt = "your_turn";
  else if (mode === "sending" || mode === "sent") prompt = "thanks";
  else if (phase === "finished") prompt = "finished";
  ui.prompt.textContent = t(prompt);
  ui.slots.replaceChildren();
  if (task && mode !== "waiting") {
    for (let i = 0; i < task.length; i++) {
      const slot = document.createElement("div");
      slot.className = "slot";
      if (taps[i]) {
        const img = document.createElement("img");
        img.src = "/assets/faces/" + taps[i] + ".svg";
        img.alt = t(taps[i]);
        slot.appendChild(img);
        slot.dataset.emotion = taps[i];
      }
      ui.slots.appendChild(slot);
    }
  }
  for (const face of ui.faces) {
    const offered = task && task.choices.includes(face.dataset.emotion);
    face.disabled = !(answering && offered && taps.length < task.length);
  }
  ui.undo.disabled = !(answering && taps.length > 0);
  ui.done.disabled = !(answering && task && taps.length === task.length);
}

for (const face of ui.faces) {
  face.addEventListener("click", () => {
    if (mode !== "answering" || !task || taps.length >= task.length) return;
    taps.push(face.dataset.emotion);
    render();
  });
}
ui.undo.addEventListener("click", () => { taps.pop(); render(); });
ui.done.addEventListener("click", () => {
  if (!task || taps.length !== task.length) return;
  const sent = socket.send({
    type: "answer",
    sequence_id: task.sequence_id,
    answer: taps.slice(),
    response_time: (performance.now() - shownAt) / 1000,
  });
  if (sent) { mode = "sending"; render(); }
});

function onMessage(m) {
  switch (m.type) {
    case "task":
      task = m; taps = []; shownAt = performance.now(); mode = "answering";
      ui.note.textContent = "";
      break;
    case "no_task":
      if (!(m.reason === "answered" && (mode === "sending" || mode === "sent"))) {
        task = null; taps = []; mode = "waiting";
      }
      break;
    case "game":
      phase = m.phase;
      break;
    case "accepted":
      if (mode === "sending") mode = "sent";
      break;
    case "rejected":
      // For the adult nearby; the child just gets the faces back when a retry makes sense.
      ui.note.textContent = t("rejected") + ": " + m.reason;
      if (mode === "sending") mode = task ? "answering" : "waiting";
      break;
  }
  render();
}

translatePage();
const socket = connectSocket("/ws/child", onMessage, (online) => {
  ui.offline.classList.toggle("hidden", online);
});
render();
