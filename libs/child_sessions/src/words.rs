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
        "belief_not_carried" => (
            "Not available: the robot's decisions do not carry a belief about the child yet \
             (its chance of success and engagement per level, and how sure it is).",
            "Nicht verfügbar: die Entscheidungen des Roboters enthalten noch keine Annahme über \
             das Kind (Erfolgschance und Engagement je Level, und wie sicher er ist).",
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
    "belief_not_carried",
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
