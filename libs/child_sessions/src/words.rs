//! The progress report's words in each language the tablet pages ship (English, German).

use crate::report::Language;

/// The word or phrase for `key` in `lang`; the key itself when there is none (a test checks
/// every key the report uses has both).
pub(crate) fn word(lang: Language, key: &str) -> &'static str {
    let (en, de) = match key {
        "progress_of" => ("Progress of", "Verlauf von"),
        "belief_title" => (
            "What the robot believes now",
            "Was der Roboter jetzt annimmt",
        ),
        "belief_no_decisions" => (
            "Not available: no decision of the robot is stored for this child (no session, or \
             no readable recording).",
            "Nicht verfügbar: von diesem Kind ist keine Entscheidung des Roboters gespeichert \
             (keine Sitzung, oder keine lesbare Aufzeichnung).",
        ),
        "belief_not_carried" => (
            "Not available: the robot did not learn about this child on its own. It chose each \
             step from the table of its group of children (the user model's cluster), so it \
             holds no belief about this child's chance of success and engagement per level.",
            "Nicht verfügbar: der Roboter hat dieses Kind nicht für sich allein kennengelernt. \
             Er wählte jeden Schritt aus der Tabelle seiner Gruppe von Kindern (dem Cluster des \
             Nutzermodells) und hat daher keine Annahme über Erfolgschance und Engagement dieses \
             Kindes je Level.",
        ),
        // {session}, {date}, {observations}: the last session planned on the belief.
        "belief_intro" => (
            "As the robot planned the last sequence of session {session} ({date}), after \
             {observations} sequences of the child's own, it believed:",
            "Als der Roboter die letzte Sequenz von Sitzung {session} ({date}) plante, nach \
             {observations} eigenen Sequenzen des Kindes, nahm er an:",
        ),
        // Non-breaking spaces keep "85 %" and "± 6" whole on a narrow tablet.
        // {level}, {length} emotions; {right} % right (± {right_sd}); {engagement} (± {engagement_sd}).
        "belief_level" => (
            "Level {level} ({length} emotions): right about {right}\u{a0}% of the time (±\u{a0}\
             {right_sd}), engagement {engagement} (±\u{a0}{engagement_sd})",
            "Level {level} ({length} Emotionen): etwa {right}\u{a0}% der Antworten richtig (±\u{a0}\
             {right_sd}), Engagement {engagement} (±\u{a0}{engagement_sd})",
        ),
        "belief_moved" => (
            "How it moved during that session, from its first sequence to its last:",
            "Wie es sich in dieser Sitzung bewegte, von der ersten Sequenz zur letzten:",
        ),
        // {level}: {from} % → {to} %, engagement {from_e} → {to_e}.
        "belief_moved_level" => (
            "level {level}: {from}\u{a0}% → {to}\u{a0}% right, engagement {from_e} → {to_e}",
            "Level {level}: {from}\u{a0}% → {to}\u{a0}% richtig, Engagement {from_e} → {to_e}",
        ),
        "belief_left_table" => (
            "It chose differently from the group's table in {left} of {planned} sequences.",
            "Er wählte in {left} von {planned} Sequenzen anders als die Tabelle der Gruppe.",
        ),
        "belief_figure_title" => (
            "Chance of a right answer per level",
            "Chance einer richtigen Antwort je Level",
        ),
        "belief_figure_right" => ("right, %", "richtig, %"),
        "belief_figure_now" => (
            "now, ± 1 standard deviation",
            "jetzt, ± 1 Standardabweichung",
        ),
        "belief_figure_start" => ("at the session's start", "zu Beginn der Sitzung"),
        "belief_caption" => (
            "Per level, the chance of a right answer the robot believes now (dark bar, its \
             whisker ± 1 standard deviation) and at that session's start (pale bar on its \
             left). The numbers are in the list above.",
            "Je Level die Chance einer richtigen Antwort, die der Roboter jetzt annimmt \
             (dunkler Balken, sein Strich ± 1 Standardabweichung), und zu Beginn dieser \
             Sitzung (heller Balken links daneben). Die Zahlen stehen in der Liste oben.",
        ),
        "problems_title" => (
            "Not read, or read in part",
            "Nicht oder nur teilweise gelesen",
        ),
        // Said only in the other languages: the messages come from the readers (and their
        // libraries' errors) as the suite's logs say them, in English.
        "problems_in_english" => (
            "The messages are in English, as in the suite's logs.",
            "Die Meldungen stehen auf Englisch, wie in den Protokollen der Suite.",
        ),
        "across_title" => ("Across sessions", "Über die Sitzungen"),
        "per_session_title" => ("Per session", "Je Sitzung"),
        "no_sessions" => (
            "No session of this child is stored yet.",
            "Von diesem Kind ist noch keine Sitzung gespeichert.",
        ),
        "score_title" => ("Score and level per session", "Punkte und Level je Sitzung"),
        "engagement_title" => ("Engagement per session", "Engagement je Sitzung"),
        "score_caption" => (
            "Top: the score (dark) of the best possible with the levels played (light). Bottom: \
             the level played, its mean with the lowest and highest. The numbers are in the \
             table below.",
            "Oben: die Punkte (dunkel) von den mit diesen Leveln möglichen (hell). Unten: das \
             gespielte Level, sein Mittel mit dem niedrigsten und höchsten. Die Zahlen stehen \
             in der Tabelle unten.",
        ),
        "engagement_caption" => (
            "The expected engagement E of the session's sequences (−1 to +1): their mean, with \
             the lowest and highest. Sessions without a face seen have no point.",
            "Das erwartete Engagement E der Sequenzen der Sitzung (−1 bis +1): ihr Mittel, mit \
             dem niedrigsten und höchsten. Sitzungen ohne erkanntes Gesicht haben keinen Punkt.",
        ),
        "session" => ("session", "Sitzung"),
        "score" => ("score", "Punkte"),
        "best_possible" => ("best possible", "möglich"),
        "level" => ("level", "Level"),
        "mean_and_range" => (
            "mean, lowest to highest",
            "Mittel, niedrigstes bis höchstes",
        ),
        "engagement" => ("engagement E", "Engagement E"),
        "col_number" => ("#", "#"),
        "col_started" => ("Started (UTC)", "Beginn (UTC)"),
        "col_score" => ("Score of max.", "Punkte von max."),
        "col_right" => ("Right", "Richtig"),
        "col_levels" => ("Levels played", "Gespielte Level"),
        "col_engagement" => ("Mean E", "Mittel E"),
        "col_feedback" => ("Feedback enc./chal.", "Feedback erm./ford."),
        "col_overrides" => ("Therapist overrides", "Eingriffe"),
        "col_pauses" => ("Pauses", "Pausen"),
        "col_proposals" => (
            "Proposals acc./repl./ran out",
            "Vorschläge angen./ersetzt/abgel.",
        ),
        "col_ended" => ("Ended", "Ende"),
        "end_finished" => ("finished", "beendet"),
        "end_stopped" => ("stopped", "gestoppt"),
        "end_emergency_stopped" => ("emergency stop", "Not-Halt"),
        "end_node_shutdown" => ("robot shut down", "Roboter heruntergefahren"),
        "end_unfinished" => ("cut off (no summary)", "abgebrochen (ohne Abschluss)"),
        "no_face" => ("no face", "kein Gesicht"),
        "none_played" => ("none played", "keine gespielt"),
        "not_recorded" => ("not recorded", "nicht aufgezeichnet"),
        "sessions_word" => ("sessions", "Sitzungen"),
        "session_word" => ("session", "Sitzung"),
        "from_stored" => (
            "Read from the session files and bags in",
            "Gelesen aus den Sitzungsdateien und Aufzeichnungen in",
        ),
        "as_of" => ("as of", "Stand"),
        "to" => ("to", "bis"),
        "recovered" => (
            "the robot's game manager was restarted during it",
            "der Spielablauf des Roboters wurde währenddessen neu gestartet",
        ),
        _ => return "",
    };
    match lang {
        Language::En => en,
        Language::De => de,
    }
}

/// Every key the report uses (checked in both languages by a test).
#[cfg(test)]
pub(crate) const KEYS: &[&str] = &[
    "progress_of",
    "belief_title",
    "belief_no_decisions",
    "belief_not_carried",
    "belief_intro",
    "belief_level",
    "belief_moved",
    "belief_moved_level",
    "belief_left_table",
    "belief_figure_title",
    "belief_figure_right",
    "belief_figure_now",
    "belief_figure_start",
    "belief_caption",
    "problems_title",
    "problems_in_english",
    "across_title",
    "per_session_title",
    "no_sessions",
    "score_title",
    "engagement_title",
    "score_caption",
    "engagement_caption",
    "session",
    "score",
    "best_possible",
    "level",
    "mean_and_range",
    "engagement",
    "col_number",
    "col_started",
    "col_score",
    "col_right",
    "col_levels",
    "col_engagement",
    "col_feedback",
    "col_overrides",
    "col_pauses",
    "col_proposals",
    "col_ended",
    "end_finished",
    "end_stopped",
    "end_emergency_stopped",
    "end_node_shutdown",
    "end_unfinished",
    "no_face",
    "none_played",
    "not_recorded",
    "sessions_word",
    "session_word",
    "from_stored",
    "as_of",
    "to",
    "recovered",
];
