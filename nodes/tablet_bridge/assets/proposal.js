// The therapist page's proposal card (supervised autonomy): when the policy is unsure, the
// game manager proposes its action with a countdown; the therapist accepts it, picks another
// level or feedback, or lets it run out (then the proposal is carried out). The countdown runs
// on this tablet's clock from the message's arrival (the bridge sends the seconds left): the
// robot's clock is never compared with the tablet's. Loaded before therapist.js, which hands
// it the bridge's proposal and game messages; the bridge checks every answer again.
"use strict";
const PROPOSAL_SETTLED_MS = 8000;  // a settled proposal stays on the card this long
const PROPOSAL_TAP_LOCK_MS = 2000; // after a tap the buttons wait this long for the answer
const proposalEl = (id) => document.getElementById(id);

let proposal = null;      // the newest proposal view from the bridge
let proposalLeft = 0;     // seconds left on its countdown
let proposalTick = 0;     // performance.now() of the countdown's last step
let proposalTapped = -Infinity; // performance.now() of the last tap on the card
let proposalTimer = null; // the countdown's interval, or the settled card's hide timeout

// "Level 2, no feedback" / "Level 2 again, encouraging feedback".
function describeAction(actionName, level, feedbackName) {
  const repeat = actionName === "encourage" || actionName === "challenge";
  return t(repeat ? "level_again" : "level_n").replace("{n}", level) + ", " + t("fb_" + feedbackName);
}

function proposalOutcome(p) {
  if (p.status === "withdrawn") return t("proposal_withdrawn");
  const what = describeAction(p.played_action_name, p.played_level, p.played_feedback_name);
  return t("proposal_" + p.status).replace("{what}", what);
}

function renderProposal() {
  const card = proposalEl("proposal");
  card.classList.toggle("hidden", !proposal);
  if (!proposal) return;
  const p = proposal;
  const paused = p.open && phase === "paused";
  const due = p.open && !paused && proposalLeft <= 0;
  const locked = performance.now() - proposalTapped < PROPOSAL_TAP_LOCK_MS;
  card.dataset.status = p.status;
  card.dataset.step = p.step;
  card.classList.toggle("open", p.open);
  card.classList.toggle("paused", paused);
  proposalEl("proposal-what").textContent =
    t("proposal_for").replace("{n}", p.step) + ": " + describeAction(p.action_name, p.level, p.feedback_name);
  proposalEl("proposal-why").textContent = t("proposal_why") + " " + (p.reason || "–") +
    " · T " + fmt(p.temperature, 1) + (p.success_std === null ? "" : " · σ " + fmt(p.success_std, 2));
  const seconds = Math.max(0, Math.ceil(proposalLeft)) + " s";
  let countdown = "";
  if (paused) countdown = t("proposal_paused") + " · " + seconds;
  else if (due) countdown = t("proposal_due");
  else if (p.open) countdown = seconds;
  else if (p.command_id) countdown = t("proposal_after").replace("{s}", fmt(p.response_time, 1));
  proposalEl("proposal-countdown").textContent = countdown;
  const share = p.open && p.countdown > 0 ? Math.max(0, Math.min(1, proposalLeft / p.countdown)) : 0;
  proposalEl("proposal-bar").firstElementChild.style.width = (100 * share).toFixed(1) + "%";
  proposalEl("proposal-outcome").textContent = p.open ? "" : proposalOutcome(p);
  const answerable = p.open && !due && !locked;
  proposalEl("proposal-accept").disabled = !answerable;
  for (const b of document.querySelectorAll("#proposal button[data-action]")) {
    b.disabled = !answerable || !p.choices.includes(b.dataset.action);
    b.classList.toggle("proposed", b.dataset.action === p.action_name);
    b.classList.toggle("played", !p.open && b.dataset.action === p.played_action_name);
  }
}

function stepCountdown() {
  const now = performance.now();
  // The game manager's countdown waits while the game is paused; it proposes again on resume.
  if (phase !== "paused") proposalLeft -= (now - proposalTick) / 1000;
  proposalTick = now;
  renderProposal();
}

function stopProposalTimer() {
  clearInterval(proposalTimer);
  clearTimeout(proposalTimer);
  proposalTimer = null;
}

function clearProposal() {
  stopProposalTimer();
  proposal = null;
  renderProposal();
}

// A proposal message from the bridge: open (count down) or settled (show what happened).
function showProposal(m) {
  // A late word on an earlier sequence never covers the current proposal.
  if (proposal && proposal.session_id === m.session_id && m.step < proposal.step) return;
  stopProposalTimer();
  proposal = m;
  proposalLeft = m.remaining;
  proposalTick = performance.now();
  proposalTapped = -Infinity;
  proposalTimer = m.open
    ? setInterval(stepCountdown, 200)
    : setTimeout(clearProposal, PROPOSAL_SETTLED_MS);
  renderProposal();
}

// The game moved on: another session, or a session that ended with the proposal still open
// (its game manager gone), hides the card.
function proposalFollowsGame(g) {
  if (!proposal) return;
  const over = !g.running && g.phase !== "paused";
  if (g.session_id !== proposal.session_id || (proposal.open && over)) clearProposal();
  else renderProposal();
}

function answerProposal(kind, extra) {
  if (!proposal || !proposal.open) return;
  proposalTapped = performance.now();
  command(kind, Object.assign({ proposal: proposal.step }, extra || {}));
  renderProposal();
  setTimeout(renderProposal, PROPOSAL_TAP_LOCK_MS + 50);
}

proposalEl("proposal-accept").addEventListener("click", () => answerProposal("accept_proposal"));
for (const l of [1, 2, 3]) {
  const b = proposalEl("proposal-level-" + l);
  b.textContent = t("level_n").replace("{n}", l);
  b.addEventListener("click", () => answerProposal("override_level", { level: l }));
}
proposalEl("proposal-encourage").addEventListener("click", () => answerProposal("override_encouraging"));
proposalEl("proposal-challenge").addEventListener("click", () => answerProposal("override_challenging"));
