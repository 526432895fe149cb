// The pages' words in each shipped language; the bridge sets <html lang> from its parameters.
"use strict";
const I18N = {
  en: {
    happy: "happy", disgusted: "disgusted", sad: "sad", angry: "angry",
    listen: "Listen to QT!", your_turn: "Your turn! Tap the faces in order.",
    thanks: "Thank you!", paused: "Pause", done: "Done", undo: "Back",
    offline: "Connecting…", finished: "All done, well played!",
    unencrypted: "Unencrypted connection (plain HTTP): the PIN and the child's results can be read by anyone on this network. Serve the pages over HTTPS (docs/install.md).",
    therapist_title: "Therapist tablet", pin: "PIN", unlock: "Unlock",
    session: "Session", user_id: "User id", user_id_hint: "User id (a code, never a name)", cluster: "Cluster (-1: default)",
    start: "Start", pause: "Pause", resume: "Resume", stop: "Stop",
    override: "Next level", estop: "EMERGENCY STOP",
    game: "Game", phase: "Phase", sequence: "Sequence", level: "Level",
    feedback: "Feedback", last_score: "Last score", session_score: "Score (of max.)", fallback: "Policy fallback",
    status: "Status", engagement: "Engagement (last minutes)", decisions: "Decisions",
    results: "Results", step: "Step", state: "State (L,F,PS)", action: "Action",
    q_values: "Q-values", probability: "p", temperature: "T", mode: "Mode",
    explored: "explored", greedy: "greedy", outcome: "Outcome", said: "Said",
    tapped: "Tapped", response_time: "Time (s)", right: "right", wrong: "wrong",
    timeout: "timeout", yes: "yes", no: "no", none: "none", encouraging: "encouraging",
    challenging: "challenging", rejected: "Refused", sent: "Sent",
    level_1: "level 1", level_2: "level 2", level_3: "level 3",
    level_1_short: "L1", level_2_short: "L2", level_3_short: "L3",
    encourage: "encourage", challenge: "challenge", encourage_short: "enc", challenge_short: "chal",
    smoothed: "smoothed", per_second: "per second",
    phase_idle: "idle", phase_deciding: "deciding", phase_giving_feedback: "feedback",
    phase_saying_sequence: "robot speaking", phase_waiting_for_answer: "child answering",
    phase_paused: "paused", phase_finished: "finished", phase_stopped: "stopped",
    phase_emergency_stopped: "EMERGENCY STOPPED", phase_unknown: "unknown",
    proposal_title: "The robot proposes", proposal_for: "Sequence {n}", proposal_why: "Why:",
    level_n: "Level {n}", level_again: "Level {n} again", fb_none: "no feedback",
    fb_encouraging: "encouraging feedback", fb_challenging: "challenging feedback",
    accept: "Accept", encourage_button: "Encourage", challenge_button: "Challenge",
    proposal_paused: "paused: the countdown waits", proposal_due: "time is up: it is carried out",
    proposal_after: "answered after {s} s", proposal_accepted: "Accepted: {what}",
    proposal_replaced: "Replaced by {what}", proposal_timed_out: "Ran out: {what} is carried out",
    proposal_withdrawn: "Withdrawn: the session ended",
  },
  de: {
    happy: "fröhlich", disgusted: "angeekelt", sad: "traurig", angry: "wütend",
    listen: "Hör QT zu!", your_turn: "Du bist dran! Tippe die Gesichter der Reihe nach.",
    thanks: "Danke!", paused: "Pause", done: "Fertig", undo: "Zurück",
    offline: "Verbinde…", finished: "Geschafft, toll gespielt!",
    unencrypted: "Unverschlüsselte Verbindung (HTTP): PIN und Ergebnisse des Kindes kann jeder in diesem Netzwerk mitlesen. Bitte die Seiten über HTTPS ausliefern (docs/install.md).",
    therapist_title: "Therapeuten-Tablet", pin: "PIN", unlock: "Entsperren",
    session: "Sitzung", user_id: "Nutzer-ID", user_id_hint: "Nutzer-ID (ein Code, nie ein Name)", cluster: "Cluster (-1: Standard)",
    start: "Start", pause: "Pause", resume: "Weiter", stop: "Stopp",
    override: "Nächstes Level", estop: "NOT-HALT",
    game: "Spiel", phase: "Phase", sequence: "Sequenz", level: "Level",
    feedback: "Feedback", last_score: "Letzte Punkte", session_score: "Punkte (von max.)", fallback: "Ersatzstrategie",
    status: "Status", engagement: "Engagement (letzte Minuten)", decisions: "Entscheidungen",
    results: "Ergebnisse", step: "Schritt", state: "Zustand (L,F,PS)", action: "Aktion",
    q_values: "Q-Werte", probability: "p", temperature: "T", mode: "Modus",
    explored: "erkundet", greedy: "gierig", outcome: "Ergebnis", said: "Gesagt",
    tapped: "Getippt", response_time: "Zeit (s)", right: "richtig", wrong: "falsch",
    timeout: "Zeit um", yes: "ja", no: "nein", none: "keins", encouraging: "ermutigend",
    challenging: "fordernd", rejected: "Abgelehnt", sent: "Gesendet",
    level_1: "Level 1", level_2: "Level 2", level_3: "Level 3",
    level_1_short: "L1", level_2_short: "L2", level_3_short: "L3",
    encourage: "ermutigen", challenge: "fordern", encourage_short: "erm", challenge_short: "ford",
    smoothed: "geglättet", per_second: "pro Sekunde",
    phase_idle: "bereit", phase_deciding: "entscheidet", phase_giving_feedback: "Feedback",
    phase_saying_sequence: "Roboter spricht", phase_waiting_for_answer: "Kind antwortet",
    phase_paused: "pausiert", phase_finished: "beendet", phase_stopped: "gestoppt",
    phase_emergency_stopped: "NOT-HALT", phase_unknown: "unbekannt",
    proposal_title: "Der Roboter schlägt vor", proposal_for: "Sequenz {n}", proposal_why: "Warum:",
    level_n: "Level {n}", level_again: "Level {n} noch einmal", fb_none: "kein Feedback",
    fb_encouraging: "ermutigendes Feedback", fb_challenging: "forderndes Feedback",
    accept: "Annehmen", encourage_button: "Ermutigen", challenge_button: "Fordern",
    proposal_paused: "Pause: der Countdown wartet", proposal_due: "Zeit um: wird ausgeführt",
    proposal_after: "beantwortet nach {s} s", proposal_accepted: "Angenommen: {what}",
    proposal_replaced: "Ersetzt durch {what}", proposal_timed_out: "Abgelaufen: {what} wird ausgeführt",
    proposal_withdrawn: "Zurückgezogen: die Sitzung ist beendet",
  },
};

function t(key) {
  const lang = I18N[document.documentElement.lang] || I18N.en;
  return lang[key] || I18N.en[key] || key;
}

// Fills every element carrying data-i18n="key" with its word.
function translatePage() {
  for (const el of document.querySelectorAll("[data-i18n]")) {
    el.textContent = t(el.dataset.i18n);
  }
}
